"""``python -m quilting`` runs the command line."""

import sys

from quilting.cli import main

sys.exit(main())
