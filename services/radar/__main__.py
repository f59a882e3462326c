import sys

from services.radar.main import main

sys.exit(main())
