"""``python -m cpgsim.cli``: the ``cpgsim`` command."""

import sys

from cpgsim.cli.main import main

sys.exit(main())
