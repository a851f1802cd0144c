"""Parameters: each declared once (:mod:`.spec`), the crane's geometry parameters (:mod:`.geometry`), and the ROS 2
parameter files the nodes and the offline CLI read alike (:mod:`.files`). No ROS import."""
