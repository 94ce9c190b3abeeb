import os
import sys

from . import main

os.environ.setdefault("EQX_ON_ERROR", "nan")
sys.exit(main())
