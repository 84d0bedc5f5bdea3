"""Load btlog's pytest plugin when pytest has not loaded it from the installed package.

Installed, btlog registers the plugin through the ``pytest11`` entry point; run from a
checkout with only ``PYTHONPATH=src`` (or with plugin autoload disabled), it is loaded
here instead. Loading it twice would be an error, hence the check.
"""

import importlib.metadata
import os


def _installed_plugin() -> bool:
    """True when pytest will load btlog's pytest11 entry point by itself."""
    if os.environ.get("PYTEST_DISABLE_PLUGIN_AUTOLOAD"):
        return False
    return any(ep.name == "btlog" for ep in importlib.metadata.entry_points(group="pytest11"))


pytest_plugins = [] if _installed_plugin() else ["btlog.testing.plugin"]
