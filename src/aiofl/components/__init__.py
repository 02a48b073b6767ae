"""The paper's pieces as scalar compiled functions.

Observers (eqs. 5, 16, 19), tracking differentiators (eqs. 18, 21, a linear prefilter),
state error feedback (eqs. 17, 20, linear), the control law (eq. 14), the metrics of
eq. (22), and the fast math they share.  Everything here is a pure function of floats;
nothing imports from another layer of aiofl.
"""
