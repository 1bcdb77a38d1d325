"""foxglove_bridge_node: the graph's topics live in Foxglove over its WebSocket protocol (foxglove-sdk)."""
