"""``python -m phloem.cli``, the same as the ``phloem`` command."""

import sys

from . import main

sys.exit(main())
