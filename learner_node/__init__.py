"""learner_node."""
