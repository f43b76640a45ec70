"""``python -m wingphoto``: the same as the ``wingphoto`` command."""
import sys

from .cli import main

sys.exit(main())
