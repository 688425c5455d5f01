"""MOOS-IvP field apps: the shoreside/vehicle brokers that bridge communities over pShare."""
