"""Meta motion graphs for streaming music (Xu, Takagi & Kawada).

- ``meta_graph``: the graph of §3.2 (nodes, mono/bi-directional edges, capacity)
- ``search``: the per-segment dynamic program of §3.3, eq. (4)-(9)
- ``engine``: the streaming step and the global-DP baseline
- ``cache``: build once, reload from disk
"""
