"""Ray as the executor of an experiment: each run is one task holding one CPU, each tournament pairing
too. The only module of pecli that imports Ray.

    with RayCluster(address=None, cpus=2) as cluster:     # embedded: a local Ray of 2 CPUs, stopped on exit
        ref = cluster.submit_run(run, zoo, markers)
        run_tournament(..., executor=cluster.play_pairings)

Embedded Ray (no ``address``) starts its processes (GCS, raylet, workers) as children of this one and
stops them on exit, Ctrl-C included. If this process is killed (SIGKILL), the GCS, the raylet and the
workers end with it (Ray starts them with ``PR_SET_PDEATHSIG``); Ray's two agents notice the raylet is
gone and exit on their own, within about 90 s. With ``address`` (``auto``, ``host:port`` or
``ray://host:port``) it joins a running cluster and leaves it running; every node must see the
experiment's ``--out`` folder at the same path (a shared file system) and have pecli installed.
"""

from __future__ import annotations

import logging
import os
import signal
import socket
import threading
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import ray
from ray.exceptions import RayError, RayTaskError

from pecli.errors import PecliError
from pecli.experiment.runs import execute_run
from pecli.experiment.spec import RunSpec
from pecli.io import atomic_write_json
from pecli.tournament import PairingJob, PairingResult, play_pairing

OBJECT_STORE_BYTES = 200 * 1024**2  # embedded Ray: runs and pairings pass small objects only
WORKER_NICENESS = "RAY_worker_niceness"  # Ray's setting of the niceness its workers add to the raylet's
RETRIES = 3  # a task whose worker or node died is run again (it continues from its durable state)
# Ray's notice on every start of a local cluster that it uses token authentication (its default): that one line
# is dropped, its other warnings (authentication disabled, a missing token) still show
TOKEN_NOTICE = "Token authentication is enabled for this Ray cluster"
TOKEN_LOGGER = "ray._private.authentication.authentication_token_setup"


def _not_the_token_notice(record: logging.LogRecord) -> bool:
    return not record.getMessage().startswith(TOKEN_NOTICE)


def _one_thread() -> None:
    import torch

    torch.set_num_threads(1)


@ray.remote(num_cpus=1, max_retries=RETRIES)
def _run_task(run: RunSpec, zoo: str, marker: str) -> dict[str, Any]:
    """Train one run (:func:`execute_run`); ``marker`` records where and since when it runs."""
    _one_thread()
    # ray.cancel stops a running task as Ctrl-C would (the run commits its state), by simulating SIGINT in the
    # worker: that does nothing if the worker inherited SIGINT ignored (a driver started in the background)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    atomic_write_json(
        marker,
        {
            "host": socket.gethostname(),
            "pid": os.getpid(),
            "started": time.time(),
            "node": ray.get_runtime_context().get_node_id(),
        },
    )
    return execute_run(run, Path(zoo))


@ray.remote(num_cpus=1, max_retries=RETRIES)
def _pairing_task(job: PairingJob) -> PairingResult:
    _one_thread()
    return play_pairing(*job)


def task_error(exc: BaseException) -> BaseException:
    """The exception a task raised (a :class:`PecliError` comes back as itself), else ``exc``."""
    cause = getattr(exc, "cause", None) if isinstance(exc, RayTaskError) else None
    return cause if isinstance(cause, BaseException) else exc


def _restore_sigterm(handler: Any) -> None:
    """Put back a SIGTERM handler of the caller's in place of Ray's (from the main thread, where Ray sets its own)."""
    if callable(handler) and threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, handler)


PROBE_TIMEOUT_S = 10.0  # how long a cluster's head may take to accept a connection


def _check_reachable(address: str) -> None:
    """:class:`PecliError` in one line when nothing answers at a ``host:port`` (or ``ray://host:port``) address,
    instead of Ray retrying for minutes; ``auto`` and addresses without a port are left to Ray."""
    host, _, port = address.removeprefix("ray://").rpartition(":")
    if not host or not port.isdigit():
        return
    if not 0 < int(port) < 65536:
        raise PecliError(f"--address {address}: the port must be from 1 to 65535")
    host = host.strip("[]")
    try:
        with socket.create_connection((host, int(port)), timeout=PROBE_TIMEOUT_S):
            pass
    except socket.gaierror as exc:
        raise PecliError(f"cannot join the Ray cluster at {address}: no host '{host}' ({exc.strerror})") from None
    except OSError as exc:
        reason = exc.strerror or str(exc) or type(exc).__name__
        raise PecliError(f"cannot join the Ray cluster at {address}: nothing answers there ({reason})") from None


class RayCluster:
    """A connection to Ray for one experiment: embedded with ``cpus`` (default: all cores) or joined at
    ``address``; a context manager that stops an embedded Ray (and disconnects from a joined one)."""

    def __init__(self, address: str | None = None, cpus: int | None = None) -> None:
        if cpus is not None and cpus < 1:
            raise PecliError(f"--cpus must be at least 1, got {cpus}")
        if address is not None and cpus is not None:
            raise PecliError("--cpus sizes an embedded Ray; a cluster joined with --address has its own CPUs")
        if address is not None:
            _check_reachable(address)  # before the caller writes anything
        self.address = address
        self.cpus = cpus
        self._connected_here = False

    def __enter__(self) -> RayCluster:
        if ray.is_initialized():  # e.g. a test connected to its own cluster already
            return self
        options: dict[str, Any] = {"log_to_driver": False}  # the runs' output stays in Ray's logs
        if not (self.address or "").startswith("ray://"):  # Ray Client passes these on to the remote driver
            options.update(include_dashboard=False, configure_logging=False)
        if self.address is None:
            options.update(num_cpus=self.cpus or os.cpu_count() or 1, object_store_memory=OBJECT_STORE_BYTES)
            # Ray starts its workers 15 steps nicer than itself; the runs are the work, so they run at the
            # driver's priority (`nice -n 10 pecli experiment run ...` puts them at 10)
            os.environ.setdefault(WORKER_NICENESS, "0")
        notices = logging.getLogger(TOKEN_LOGGER)
        if _not_the_token_notice not in notices.filters:
            notices.addFilter(_not_the_token_notice)
        # ray.init puts a SIGTERM handler of its own (exit code 15) in place of the caller's: the caller's comes back
        previous = signal.getsignal(signal.SIGTERM)
        try:
            # "local" starts a new Ray even where `ray start` left a cluster's address behind (None would join it)
            ray.init(address=self.address or "local", **options)
        except SystemExit as exc:  # SIGTERM while Ray starts: the caller's handler gets it, as it would any other time
            if exc.code != signal.SIGTERM or not callable(previous):
                raise
            _restore_sigterm(previous)
            ray.shutdown()  # what ray.init had started
            previous(signal.SIGTERM, None)
            raise
        except (ConnectionError, RayError, ValueError, RuntimeError) as exc:
            where = f"the Ray cluster at {self.address}" if self.address else "an embedded Ray"
            raise PecliError(f"cannot start or join {where}: {str(exc).splitlines()[0] if str(exc) else exc}") from None
        finally:
            _restore_sigterm(previous)
        self._connected_here = True
        return self

    def __exit__(self, *exc: object) -> None:
        if self._connected_here:
            ray.shutdown()
            self._connected_here = False

    @property
    def embedded(self) -> bool:
        return self.address is None

    def total_cpus(self) -> int:
        return int(ray.cluster_resources().get("CPU", 0))

    def nodes(self) -> int:
        return sum(1 for node in ray.nodes() if node.get("Alive"))

    # -- runs ------------------------------------------------------------------------------------
    def submit_run(self, run: RunSpec, zoo: Path, marker: Path) -> ray.ObjectRef:
        return _run_task.remote(run, str(zoo.resolve()), str(marker.resolve()))

    @staticmethod
    def wait(refs: Sequence[ray.ObjectRef], timeout: float) -> list[ray.ObjectRef]:
        """The refs among ``refs`` that are finished, after waiting at most ``timeout`` seconds for one."""
        if not refs:
            return []
        ready, _ = ray.wait(list(refs), num_returns=len(refs), timeout=timeout)
        return ready

    @staticmethod
    def result(ref: ray.ObjectRef) -> Any:
        """The task's return value; the exception it raised otherwise (a :class:`PecliError` as itself)."""
        try:
            return ray.get(ref)
        except RayError as exc:
            raise task_error(exc) from None

    @staticmethod
    def stop(refs: Sequence[ray.ObjectRef], grace: float) -> None:
        """Interrupt the tasks not finished yet like Ctrl-C (a run commits its state of the moment), then wait
        at most ``grace`` seconds for them to end. A finished task is left alone: ``ray.cancel`` racing a task's
        completion can abort the driver inside Ray."""
        if not refs:
            return
        _, running = ray.wait(list(refs), num_returns=len(refs), timeout=0)
        for ref in running:
            try:
                ray.cancel(ref)
            except RayError:
                pass
        if running:
            ray.wait(running, num_returns=len(running), timeout=grace)

    # -- tournament pairings ------------------------------------------------------------------------
    def play_pairings(self, jobs: Sequence[PairingJob]) -> Iterator[tuple[int, PairingResult | PecliError]]:
        """A :data:`pecli.tournament.PairingExecutor`: every job a Ray task, results as they finish.

        Stopped early (Ctrl-C, SIGTERM, an error), it leaves the tasks still out to end with the driver's
        connection to Ray (leaving the :class:`RayCluster` block ends them): ``ray.cancel`` on a pairing that
        finishes at that moment can abort the driver inside Ray (a race in Ray's task manager), and pairings
        finish many times a second.
        """
        refs = {_pairing_task.remote(job): index for index, job in enumerate(jobs)}
        pending = list(refs)
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            for ref in ready:
                try:
                    yield refs[ref], self.result(ref)
                except PecliError as exc:
                    yield refs[ref], exc
                except Exception as exc:  # a worker lost for good, a MemoryError in the task: that pairing fails
                    yield (
                        refs[ref],
                        PecliError(
                            f"a pairing failed on Ray ({type(exc).__name__}: "
                            f"{str(exc).splitlines()[0] if str(exc) else exc}); Ray's logs are "
                            "in /tmp/ray/session_latest/logs/"
                        ),
                    )
