import sys

from aeb_radar_camera.services.brake.main import main

sys.exit(main())
