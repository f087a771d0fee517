"""The worst-case family (Berger et al. 2010): the first-order error map of joint clearances,
interval arithmetic, the certified branch and bound, the exact model and the statistics of
uniformly distributed clearances."""
