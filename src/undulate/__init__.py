"""undulate: rods printed on a pre-stretched textile, released until they buckle.

Units everywhere: mm, MPa (= N/mm^2), N, s (energies in N*mm).
Pipeline: model -> mesh -> mechanics -> solve -> analysis -> study -> interfaces.
"""

__version__ = "0.1.0"
