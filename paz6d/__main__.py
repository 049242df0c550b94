"""``python -m paz6d ...``: the same command line as the ``paz6d`` script."""

from paz6d.cli import main

raise SystemExit(main())
