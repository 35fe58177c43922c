"""flock_swarm_examples: a law and a leader model added to flock_swarm from outside."""
