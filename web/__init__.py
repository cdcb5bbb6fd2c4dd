"""The browser front end: static files (index.html, js/, vendored three.js) served by :mod:`service.web`."""
