"""hasel_sysid: rclpy nodes of the HASEL toolkit (see package.xml)."""
