"""Camera service: frames from a RealSense, any OpenCV capture, an image folder or a
source plugin, published as JPEG with capture stamps; CameraInfo from the calibration."""
