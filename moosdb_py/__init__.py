"""MOOS itself in pure Python: wire codec, MOOSDB, client, MOOSApp, mission files and the MOOS essentials."""
