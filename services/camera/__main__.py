import sys

from services.camera.main import main

sys.exit(main())
