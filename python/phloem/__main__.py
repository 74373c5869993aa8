"""``python -m phloem``, the same as the ``phloem`` command."""

import sys

from .cli import main

if __name__ == "__main__":  # importing the module (doctest collection does) runs nothing
    sys.exit(main())
