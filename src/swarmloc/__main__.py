"""``python -m swarmloc`` is the ``swarmloc`` command."""

from swarmloc.deploy.cli import main

raise SystemExit(main())
