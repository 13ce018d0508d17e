import sys

from twb.main import main

sys.exit(main())
