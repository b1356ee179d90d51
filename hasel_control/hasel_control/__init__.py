"""hasel_control: rclpy nodes of the HASEL toolkit (see package.xml)."""
