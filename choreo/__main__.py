"""`python -m choreo` is the same program as the `choreo` console script."""

import sys

from choreo.cli import main

sys.exit(main())
