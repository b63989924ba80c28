"""`jaxskin edit`: an interactive editor in the browser (issue 15).

A local web application over the same renderer as `jaxskin render`: sliders for every
scene value, direction-field edits picked on the mesh (Bando 2001 §3.1), cosmetic layers
painted on the face (Huang et al. 2013 §3), the state in the page's URL, Save as a scene
file that `jaxskin render` reproduces byte for byte. `state` holds the session (and
renders), `document` changes its scene document, `brush` paints thickness maps,
`jaxskin.toml_writer` writes scenes, `server` is the HTTP API (aiohttp), `static/` the page
(plain HTML, CSS and JavaScript: no build step, nothing fetched from the network).
"""

from __future__ import annotations

__all__: list[str] = []
