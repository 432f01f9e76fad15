"""``python -m pecli`` runs the command-line interface."""

from pecli.cli import main

if __name__ == "__main__":
    main()
