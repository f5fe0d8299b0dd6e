"""``python -m holoprobe`` runs the command-line interface."""

from holoprobe.cli import main

main()
