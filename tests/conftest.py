import os

# Read by dm_control at import: nothing in the tests renders.
os.environ.setdefault("MUJOCO_GL", "disable")
