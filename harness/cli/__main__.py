"""``python -m harness.cli``: the ``cpgsim`` command."""

import sys

from harness.cli.main import main

sys.exit(main())
