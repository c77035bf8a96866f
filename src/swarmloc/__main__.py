"""``python -m swarmloc`` is the ``swarmloc`` command."""

from swarmloc.deploy.cli import console_main

console_main()
