import sys

from cananalyze.cli.main import program

sys.exit(program())
