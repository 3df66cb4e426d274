"""From simulation to a real arm: joint logs, excitation, system identification, physics profiles.

* :mod:`~armreach_core.sim2real.joint_log`: the joint-log format (CSV and NPZ), one reader and one writer;
* :mod:`~armreach_core.sim2real.excitation`: safe excitation sequences (steps and chirps per joint);
* :mod:`~armreach_core.sim2real.profile`: physics profiles (YAML) and applying one to a backend;
* :mod:`~armreach_core.sim2real.replay`: playing logged commands on a backend;
* :mod:`~armreach_core.sim2real.sysid`: fitting a profile to joint logs, and its report.

This package's ``__init__`` imports nothing, so the env can use the profile module alone.
"""
