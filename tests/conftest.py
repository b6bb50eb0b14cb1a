import os
import tempfile

# keep the mechanics cache out of the user's home during tests unless CI set one
os.environ.setdefault("OSMOBULGE_CACHE_DIR", os.path.join(tempfile.gettempdir(), "osmobulge-test-cache"))
