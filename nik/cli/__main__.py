"""``python -m nik.cli``: the ``nik`` command line (:func:`nik.cli.main`)."""

import sys

from nik.cli import main

sys.exit(main())
