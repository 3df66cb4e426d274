"""PyBullet backend for armreach (registered through the ``armreach`` entry-point group).

The package, one job per module:

* :mod:`~armreach_pybullet.engine`: ``pybullet`` imported with its C output sent to the log;
* :mod:`~armreach_pybullet.loader`: physics settings, the ground, the arm loaded from its URDF;
* :mod:`~armreach_pybullet.servo`: joint and link indices by name, the position motors, the damping bound;
* :mod:`~armreach_pybullet.friction`: Coulomb joint friction as constraints;
* :mod:`~armreach_pybullet.world`: boxes, markers, contacts and surface friction by name;
* :mod:`~armreach_pybullet.render`: offscreen pictures and the window's camera;
* :mod:`~armreach_pybullet.backend`: the :class:`~armreach_core.backend.Backend` facade over them;
* :mod:`~armreach_pybullet.probes`: the bare loop and client count of ``armreach bench`` and ``soak``.
"""
