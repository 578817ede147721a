import sys

from garage_mj.cli import main

sys.exit(main())
