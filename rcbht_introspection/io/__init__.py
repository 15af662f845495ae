"""File formats: HIRO trial folders, the original RCBHT text records, rosbag2."""
