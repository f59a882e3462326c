import sys

from services.vehicle.main import main

sys.exit(main())
