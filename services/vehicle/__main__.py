import sys

from aeb_radar_camera.services.vehicle.main import main

sys.exit(main())
