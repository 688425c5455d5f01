"""Generic MOOS-IvP marine apps: the vehicle simulator, the PID controller, the node reporter."""
