import os
import tempfile

# keep the mechanics cache out of the user's home during tests unless CI set one
os.environ.setdefault("OSMOBULGE_CACHE_DIR", os.path.join(tempfile.gettempdir(), "osmobulge-test-cache"))
# the CLI's errors are boxed by typer (rich) at the terminal's width: wide enough that a long tmp path (a pytest-xdist
# worker's) does not wrap the words the tests look for onto two lines
os.environ["TERMINAL_WIDTH"] = "400"  # (typer reads it when imported)
