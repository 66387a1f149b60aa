"""The dashboard's browser files (index.html, app.js, style.css), installed as package data.

The backend finds them with ``importlib.resources.files("frontend_assets")``, so a regular
(non-editable) ``pip install .`` serves the same files as a checkout.
"""
