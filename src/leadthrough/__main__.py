"""``python -m leadthrough``: same as the ``leadthrough`` console script."""

import sys

from leadthrough.cli import main

sys.exit(main())
