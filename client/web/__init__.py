"""The browser page's static files (index.html, its scripts and styles).

Not Python: this file only lets the wheel ship the folder as ``quilting.web``, from where the
service serves it at ``/``.
"""
