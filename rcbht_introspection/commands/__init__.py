"""CLI subcommands: thin argument parsing over the core modules.

Every command module is imported to build `rcbht --help`, so each one imports the engine,
rclpy, rosbags, MuJoCo or matplotlib inside the function that runs the command: `--help` and a
one-line error stay at about half a second. Nowhere else in the package are imports deferred
for speed.
"""
