"""``python -m estim``: the ``estim`` command (:mod:`estim.cli.launch`)."""

from estim.cli.launch import main

main()
