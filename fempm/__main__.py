import sys

from fempm.cli import main

sys.exit(main())
