"""``python -m mpcdrive``: the command line (same as the ``mpcdrive`` command)."""

from .cli import main

main()
