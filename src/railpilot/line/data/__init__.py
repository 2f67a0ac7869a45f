"""Shipped line files (heavy_haul.toml, metro.toml) and the generator of the heavy-haul one."""
