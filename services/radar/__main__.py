import sys

from aeb_radar_camera.services.radar.main import main

sys.exit(main())
