import sys

from ddsolve.cli import main

sys.exit(main())
