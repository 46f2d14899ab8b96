"""The one exception type for problems with the user's input.

A :class:`ViscxError` carries a one-line message meant for a person; the CLI prints
it as ``viscx: error: <message>`` and exits with status 2. Anything else that
escapes is a bug in viscx.

A message about a parameter names it as the library spells it (``light_face``); the
CLI, which calls the same functions, renames it to its option (``--light-face``):
:class:`ParameterError` keeps the names as fields of a template for that.
"""

import string


class ViscxError(Exception):
    """Bad input: a file that is missing, unreadable, of the wrong kind, or a
    scene or option that cannot be used. The message is one line."""

    exit_code = 2


class ParameterError(ViscxError):
    """Bad value of a parameter, the parameters named as fields of ``template``
    (``"{light_face} 99 is out of range"``; literal braces doubled). The message
    (``str``) spells them as the library does; :meth:`renamed` as a caller wants.

    Parameters
    ----------
    template : str
    """

    def __init__(self, template):
        self.template = template
        super().__init__(self.renamed({}).args[0])

    @property
    def params(self):
        """The parameters the message names, in order: list of str."""
        return [name for _, name, _, _ in string.Formatter().parse(self.template) if name]

    def renamed(self, names):
        """A :class:`ViscxError` whose message spells each parameter ``p`` as
        ``names.get(p, p)`` (e.g. ``{"light_face": "--light-face"}``)."""
        return ViscxError(self.template.format_map({p: names.get(p, p) for p in self.params}))


def literal(value):
    """``str(value)`` with its braces doubled: text inside a :class:`ParameterError` template."""
    return str(value).replace("{", "{{").replace("}", "}}")
