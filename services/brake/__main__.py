import sys

from services.brake.main import main

sys.exit(main())
