"""hasel_driver: rclpy nodes of the HASEL toolkit (see package.xml)."""
