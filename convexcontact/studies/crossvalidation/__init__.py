"""Cross-validation: another answer against the exact one.

:mod:`.compare` compares two solutions on one mesh (``convexcontact compare``), :mod:`.peer` another code's
output file on its own mesh, :mod:`.sfepy_peer` sfepy's penalty contact run as that peer (``study sfepy``),
:mod:`.sweeps` the penalty and ε errors over decades (``study sweep``).
"""
