import sys

from services.fusion.main import main

sys.exit(main())
