import sys

from servant_tui.main import main

sys.exit(main())
