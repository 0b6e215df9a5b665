"""``python -m mpcdrive.cli``: the command line (same as the ``mpcdrive`` command)."""

from . import main

main()
