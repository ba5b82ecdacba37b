"""``python -m iloci`` is the ``iloci`` command."""

import sys

from iloci.cli import main

sys.exit(main())
