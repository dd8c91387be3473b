"""hydrobuckle's version, in a module of its own so that any room can read it without importing the
package's re-exported API (:mod:`app.api`, top of the layers)."""

__version__ = "0.1.0"
