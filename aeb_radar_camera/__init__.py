"""The AEB stack as installed: the repository's `common/`, `services/`, `tools/` and
`deploy/` under one name that cannot collide with another project's `common` or `tools`
in site-packages. In a checkout these are links to the top-level folders, so the code
has one place and one import name (`aeb_radar_camera.common...`) in both.
"""
