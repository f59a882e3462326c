import sys

from aeb_radar_camera.services.fusion.main import main

sys.exit(main())
