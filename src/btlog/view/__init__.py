"""The web viewer: ``btlog view`` serves it, ``btlog view --export`` writes it as one file.

``model`` turns the read model into the JSON the page reads; ``server`` serves the page
and that JSON on the loopback interface; ``export`` inlines the page and a run's events
into one self-contained HTML file. The page itself (plain JS, CSS and SVG) is in
``static/``.
"""
