"""What goes to disk and how it is trusted, pure numpy: atomic writes, content fingerprints, resumable stores.

* ``atomic.py``: atomic file writes (a reader sees the old file or the new one, never a torn one).
* ``identity.py``: content fingerprints of everything that determines the numbers; the only hasher.
* ``store.py``: resumable, verified on-disk results and content-addressed caches.
* ``imageio.py``: OpenEXR (float) and PNG (8/16-bit) image files with metadata.
"""
