"""curriculum_node."""
