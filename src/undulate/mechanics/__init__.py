"""Mechanics stage: energies as pure JAX functions of one element, and their assembly.

Where things are: the fabric's membrane, bending and dead loads (``fabric.py``, its material
law in ``material.py``), the bonded rod (``rod.py``), the element groups of a mesh
(``build.py``), per-element kernels from autodiff or strain forms (``forms.py``), the rods'
Hessian through their frames (``frames.py``), the global energy, gradient and sparse Hessian
(``assemble.py``, whose seam is :class:`~undulate.mechanics.assemble.EnergyTerm`), the mixed
Newton's carried stresses and merit (``mixed.py``), runs batched together (``batched.py``) and
the kernels kept on disk (``compiled.py``).
"""
