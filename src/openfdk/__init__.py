"""openfdk — open-source Force-dependent Kinematics.

See the README and docs/ for the user guide; DESIGN notes are cited as paper equation
numbers (Andersen et al., J Biomech Eng 2017) in the code comments.
"""

__version__ = "0.1.0"
