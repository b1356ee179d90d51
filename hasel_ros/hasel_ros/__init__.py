"""hasel_ros: the ROS plumbing every package of the toolkit shares (QoS, stamps, parameters,
diagnostics, the Deadline timer, a node's main); see :mod:`hasel_ros.rosutil`."""
