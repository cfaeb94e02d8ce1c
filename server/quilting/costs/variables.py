"""The environment variables the backends read, in a module of their own so that the
registry and the ``gl`` backend (which the registry loads on demand) both take them from here
without importing each other."""

#: Environment variable naming the backend ``auto`` stands for (an operator's override).
BACKEND_VARIABLE = "QUILTING_BACKEND"

#: The EGL device index the gl backend opens (one worker process per GPU sets it).
GL_DEVICE_VARIABLE = "QUILTING_GL_DEVICE"
