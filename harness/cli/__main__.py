"""``python -m cpgsim.harness.cli``: the ``cpgsim`` command."""

import sys

from cpgsim.harness.cli.main import main

sys.exit(main())
