"""An AeroDaaS plug-in package: one module per extension point (see docs/extending.md of AeroDaaS).

* :mod:`.gas` — sensor type ``gas_concentration`` (a Gaussian gas plume sampled at the vehicle's position);
* :mod:`.wind` — vehicle backend ``gusty_sim`` (the embedded simulator with wind gusts);
* :mod:`.rover` — vehicle backend ``ground_rover`` (a kinematic ground rover written from scratch on the backend
  contract; it needs no take-off);
* :mod:`.threshold` — analytics ``gas_threshold`` (gas reading -> hover-here navigation command);
* :mod:`.plume` — analytics ``gas_plume`` (gas readings -> a typed status per reading, a ``crossing`` named output
  and ``plume_entered``/``plume_left`` events);
* :mod:`.probe` — analytics ``frame_probe`` (a cheap per-frame analytics for the analytics scheduler to place);
* :mod:`.sweep` — trajectory scheduler ``eastward_sweep`` (an UNORDERED survey flown west to east);
* :mod:`.placement` — analytics scheduler ``THIN_EDGE_FIFO`` (EDGE_FIFO that sheds every k-th frame).

Each is declared as an entry point in ``pyproject.toml``; nothing here is imported by AeroDaaS until a run names it.
"""
