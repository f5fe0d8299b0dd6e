"""Field propagation: angular spectrum, Rayleigh integrals and fast projection.

Each algorithm lives in a private module and is re-exported here.
"""

__all__: list[str] = []
