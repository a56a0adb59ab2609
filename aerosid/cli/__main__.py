"""``python -m aerosid.cli ...`` runs the ``aerosid`` command."""
import sys

from aerosid.cli import main

if __name__ == "__main__":
    sys.exit(main())
