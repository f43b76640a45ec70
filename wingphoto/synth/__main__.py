"""``python -m wingphoto.synth [OUT_DIR]``: regenerate the data samples."""
from .samples import _main

raise SystemExit(_main())
