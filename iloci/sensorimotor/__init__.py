"""From a pen trajectory to network input: the paper's sensorimotor path.

``preprocess``  smoothing, resampling, scaling and fitting into the drawing plane;
``robots``      the Nao V3.2 right-arm URDF and its drawing plane;
``pipeline``    demonstration -> :class:`~iloci.sensorimotor.pipeline.Motion` (IK);
``encoding``    motion <-> scaled relative displacements [dy, dz, dq1..dq4];
``simulation``  what every simulator plugin shares: input checks, servo
                set-points and the tracking loop, the picture's camera and style.

Everything here is numpy/scipy; the IK solver and the simulators are plugins.
"""
