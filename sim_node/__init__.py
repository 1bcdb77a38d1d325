"""sim_node."""
