"""What ``jaxgrav match`` says of a status bit: the command's words, not the library's.

:data:`jaxgrav.match.STATUS` describes each bit for a library user, naming the
configuration fields that set its threshold (``max_iter``, ``max_sigma_m``,
``stencil_size``, ``missing='gaps'`` ...). A command-line user sets none of them;
:data:`CLI_STATUS` says the same in plain words and the command's options, and
:func:`status_text` picks the text of a bit.
"""

from jaxgrav.match import STATUS

__all__ = ["CLI_STATUS", "status_text"]

CLI_STATUS = {
    8: "the best candidate lies on the edge of the search region (the drift may exceed "
       "--drift-radius)",
    16: "ICCP did not converge within its iteration limit",
    256: "a step's accepted displacements exceed the chains' reach from one fix to the next "
         "(those pairs were not considered)",
    512: "fix rejected: the readings do not pin the position down (the fix's 1-sigma is "
         "wider than 3 km with --map-error, or not 10 % narrower than the spread of the "
         "searched region itself); INS track kept",
    1024: "fix rejected: a distinct second position fits the readings nearly as well; INS "
          "track kept",
    2048: "fix rejected: the best candidate's misfit is inconsistent with the stated --noise "
          "and --map-error; INS track kept",
    4096: "fix rejected: much of the position's probability lies at the edge of the search "
          "region (the drift may exceed --drift-radius); INS track kept",
    32768: "fix rejected: more than half of the fix's readings lie over survey gaps of the "
           "map (--missing gaps); INS track kept",
    65536: "fix rejected: the fix lies farther from the INS track than the drift allows "
           "(1.5 x --drift-radius); INS track kept",
}
"""The texts of :data:`jaxgrav.match.STATUS` that name library settings, reworded."""


def status_text(bit):
    """The command's text for a status ``bit`` of :data:`jaxgrav.match.STATUS`.

    Parameters
    ----------
    bit : int
        A key of :data:`jaxgrav.match.STATUS`.

    Returns
    -------
    str
        :data:`CLI_STATUS`'s text where the library's names its settings, else the
        library's.
    """
    return CLI_STATUS.get(bit, STATUS[bit])
