import sys

from semmap_pp.cli import console_main

sys.exit(console_main())
