"""``glocal-ros bench sim|learner|graph``: each writes its table under bench/results/ (see README, "Benchmarks")."""
