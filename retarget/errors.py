"""The one exception type the library raises for bad input.

`RetargetError` subclasses `ValueError` (bad input is a value problem, as in trimesh and
scikit-learn) so callers may catch either; the server maps it to an HTTP 4xx whose
`detail` is the message, so every message names the parameter and the offending value.
"""


class RetargetError(ValueError):
    """Input the library refuses: the message says which input and why."""
