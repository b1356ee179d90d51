"""sim_plant: rclpy nodes of the HASEL toolkit (see package.xml)."""
