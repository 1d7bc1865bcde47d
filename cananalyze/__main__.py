import sys

from cananalyze.cli.main import main

sys.exit(main())
