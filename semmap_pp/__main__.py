import sys

from semmap_pp.cli import main

sys.exit(main())
