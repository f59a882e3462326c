import sys

from aeb_radar_camera.services.camera.main import main

sys.exit(main())
