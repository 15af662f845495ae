"""rclpy adapters only: parameters, topics, message conversions."""
