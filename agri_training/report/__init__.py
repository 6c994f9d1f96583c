"""The evaluation report (``agri report``): one page over every suite, baseline and learned policy.

Above ``leaderboard``: :mod:`.page` builds the page (tables, paired comparisons, learning curves) and calls
one module per env family for its section of figures: :mod:`.rover`, :mod:`.coverage`, :mod:`.chain`,
:mod:`.arm`.
"""
