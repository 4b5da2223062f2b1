"""``python -m vibro`` runs the command line."""

import sys

from vibro.cli import main

sys.exit(main())
