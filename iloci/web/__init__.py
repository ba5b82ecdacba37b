"""iloci's web app (``iloci serve``): see :mod:`iloci.web.app`."""
