"""``python -m delaykit.cli``: the same as the ``delaykit`` script."""

import sys

from .app import main

__all__: list[str] = []

if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
