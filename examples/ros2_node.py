"""A ROS 2 node that drives a car with an exported pecli policy (an example: adapt topics and messages).

It is what the paper's robot experiment needs (section VI): motion capture gives both cars' poses at
10 Hz, the node runs the exported policy once per control tick and publishes the command. Only
``numpy``, ``onnxruntime`` and ``pecli.runtime`` are needed on the robot besides ROS 2 itself::

    pecli export onnx zoo/robots-run/pursuer/final.zip          # on the training machine
    pip wheel --no-deps -w dist .                               # there too, in pecli's checkout
    scp dist/pecli-*.whl zoo/robots-run/pursuer/final.onnx* robot:   # the wheel, the model and its .onnx.json
    pip install --no-deps pecli-*.whl && pip install numpy onnxruntime   # on the robot
    python3 ros2_node.py --ros-args -p model:=final.onnx -p own_odom:=/f1tenth/odom \\
        -p opponent_odom:=/jetracer/odom -p drive:=/f1tenth/drive

Subscribes:   ``own_odom``, ``opponent_odom`` (nav_msgs/Odometry, world frame, e.g. from motion capture)
              ``reset`` (std_msgs/Empty): a new game starts; the policy forgets its past
Publishes:    ``drive`` (ackermann_msgs/AckermannDriveStamped): the steering velocity and acceleration
              the policy commands, with the steering angle and speed they lead to after one tick

The car's steering angle is not in Odometry; this node integrates its own steering commands for
it (replace that with a measured angle if your car reports one). The sensor's range and field of
view (from the sidecar) decide whether the opponent is seen, as in simulation.
"""

from __future__ import annotations

import math

import numpy as np
import rclpy
from ackermann_msgs.msg import AckermannDriveStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from std_msgs.msg import Empty

from pecli.runtime import Controller


def yaw_of(odom: Odometry) -> float:
    """Heading (rad) from the pose's quaternion (rotation about z)."""
    q = odom.pose.pose.orientation
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def car_state(odom: Odometry, steering: float = 0.0) -> np.ndarray:
    """A car's SI state (s_x m, s_y m, delta rad, v m/s, psi rad); twist.linear.x is the forward speed."""
    p = odom.pose.pose.position
    return np.array([p.x, p.y, steering, odom.twist.twist.linear.x, yaw_of(odom)])


def point_mass_state(odom: Odometry) -> np.ndarray:
    """A point mass's SI state (s_x m, s_y m, v_x m/s, v_y m/s), velocity in the world frame."""
    p, v, psi = odom.pose.pose.position, odom.twist.twist.linear, yaw_of(odom)
    return np.array([p.x, p.y, v.x * math.cos(psi) - v.y * math.sin(psi), v.x * math.sin(psi) + v.y * math.cos(psi)])


class PecliDriver(Node):
    """Runs :class:`pecli.runtime.Controller` at the model's control rate (10 Hz for the robots scenario)."""

    def __init__(self) -> None:
        super().__init__("pecli_driver")
        model = self.declare_parameter("model", "final.onnx").value
        seed = self.declare_parameter("seed", 0).value
        self.controller = Controller.load(model, seed=seed)
        sidecar = self.controller.model.sidecar
        own, opponent = sidecar["scenario"]["config"][sidecar["role"]], self._opponent_params(sidecar)
        self.own_is_car, self.opponent_is_car = own["kind"] == "car", opponent["kind"] == "car"
        if not self.own_is_car:
            raise SystemExit("this example drives a car; a point-mass player needs another command message")
        self.steer_limits = (own["steer_min"], own["steer_max"])
        self.speed_limits = (own["v_min"], own["v_max"])
        self.steering = 0.0  # integrated from our own steering-velocity commands
        self.own: Odometry | None = None
        self.opponent: Odometry | None = None

        self.create_subscription(Odometry, self.declare_parameter("own_odom", "own/odom").value, self._on_own, 10)
        self.create_subscription(
            Odometry, self.declare_parameter("opponent_odom", "opponent/odom").value, self._on_opponent, 10
        )
        self.create_subscription(Empty, self.declare_parameter("reset", "pecli/reset").value, self._on_reset, 10)
        self.drive = self.create_publisher(AckermannDriveStamped, self.declare_parameter("drive", "drive").value, 10)
        self.dt = self.controller.model.dt
        self.create_timer(self.dt, self.tick)  # one decision per tick, as in simulation (dt = 0.1 s: 10 Hz)
        self.get_logger().info(
            f"{sidecar['role']} from {model}: {sidecar['belief']} belief, "
            f"{1.0 / self.dt:.0f} Hz, sensor {sidecar['sensor']['range_m']} m"
        )

    @staticmethod
    def _opponent_params(sidecar: dict) -> dict:
        other = "evader" if sidecar["role"] == "pursuer" else "pursuer"
        return sidecar["scenario"]["config"][other]

    def _on_own(self, msg: Odometry) -> None:
        self.own = msg

    def _on_opponent(self, msg: Odometry) -> None:
        self.opponent = msg

    def _on_reset(self, _: Empty) -> None:
        self.controller.reset()
        self.steering = 0.0
        self.get_logger().info("new game")

    def tick(self) -> None:
        """One control tick: the latest estimates in, the command out."""
        if self.own is None:
            return  # no state estimate yet
        own = car_state(self.own, self.steering)
        opponent = None
        if self.opponent is not None:
            opponent = car_state(self.opponent) if self.opponent_is_car else point_mass_state(self.opponent)
        steering_velocity, acceleration = self.controller.step(own, opponent)  # rad/s, m/s^2
        self.steering = float(np.clip(self.steering + steering_velocity * self.dt, *self.steer_limits))
        msg = AckermannDriveStamped()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.drive.steering_angle = self.steering
        msg.drive.steering_angle_velocity = abs(float(steering_velocity))
        msg.drive.speed = float(np.clip(own[3] + acceleration * self.dt, *self.speed_limits))
        msg.drive.acceleration = float(acceleration)
        self.drive.publish(msg)


def main() -> None:
    rclpy.init()
    node = PecliDriver()
    try:
        rclpy.spin(node)
    finally:
        node.destroy_node()
        rclpy.shutdown()


if __name__ == "__main__":
    main()
