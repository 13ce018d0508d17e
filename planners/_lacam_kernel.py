"""The compiled core of :mod:`planners.lacam`: LaCAM* over a graph with PIBT as its configuration generator.

docs/planners.md, "Several robots: LaCAM", has the overview; :mod:`planners.lacam` the grid, the
robots' starts and goals and the schedule.  This module is numba only and is imported when a plan is
made (never by the server, which lists the planner without loading numba).

The graph is a table of neighbours ``nbr`` ``(V, 4)`` (-1 where there is none; 4-connected grids) with
each vertex's count ``deg``.  A *configuration* is one vertex per agent.

**LaCAM** (Okumura, AAAI 2023) searches configurations depth first.  A high-level node holds a
configuration, the agents' PIBT priorities and, lazily, a low-level search over *constraints* (agent
``who`` goes to vertex ``where``): each visit of a node pops one constraint set from its queue (breadth
first; the root is the empty set), adds its children (the next agent in the node's order, at each of
its candidate vertices) and asks PIBT for a successor configuration that respects it.  Because the
low-level search eventually pins every agent at every candidate, every successor of every reached
configuration is eventually generated: the search is complete (it ends with a solution, or proves there
is none by running out of nodes), while PIBT's first proposal is usually good enough that a node is
visited once.  A configuration met again is pushed on the open stack again (as LaCAM's code does), so
the search keeps moving.

**LaCAM*** (IJCAI 2023) keeps searching after the first solution: every node has a cost ``g`` from the
start (sum of loss: an agent costs 1 per step unless it stays at its goal), the explored graph keeps its
edges in both directions, and reaching a known configuration relaxes ``g`` along them (a Dijkstra sweep
that re-parents nodes).  Nodes whose ``g + h`` (``h``: the sum of the agents' distances to their goals,
admissible) cannot beat the best solution are pruned.  The refinement here is bounded by an iteration
budget (deterministic) and the wall-clock budget; when the open stack empties the solution is optimal
for the sum of loss.  Now and then (1 in 10 after the first solution) a known configuration sends the
search back to the start instead, as the reference implementation does, so that refinement does not
stay in one region.

**PIBT** (Okumura et al., AIJ 2022) gives every agent, in priority order, its best free neighbour by
distance to its goal (random tie-breaks); an agent that takes a vertex another agent stands on makes
that agent move first (priority inheritance), and backtracks when it cannot.  With ``swap``, the swap
operation of "Engineering LaCAM*" (AAMAS 2024): an agent that meets another head-on in a corridor,
where the two must pass each other, pulls it along (moving away from its goal) until there is room to
swap.  Vertex and swap (edge) conflicts are never produced.

**Rotations** (agents moving along a cycle, each into the vertex the next one leaves) are valid in the
usual MAPF model but cannot be executed by the testbed's order of passage (each robot would wait for
the one ahead to arrive first: :mod:`planners.dependencies`); with ``rotations`` False (the field's
plans) PIBT avoids them and a configuration that has one is refused.  Following (an agent moving into
the vertex another leaves, in a chain that ends) is allowed either way.
"""

from __future__ import annotations

import time

import numpy as np
from numba import njit, objmode

__all__ = ["SOLVED", "UNSOLVABLE", "BUDGET", "bfs_distances", "lacam", "transitions_valid"]

#: statuses of :func:`lacam`
SOLVED, UNSOLVABLE, BUDGET = 0, 1, 2
_INF = 1 << 30
#: the probability (after the first solution) that a known configuration restarts the search at the start
_RESTART = 0.1


@njit(cache=True)
def _now() -> float:
    """Wall time (s), read from compiled code."""
    with objmode(t="float64"):
        t = time.perf_counter()
    return t


@njit(cache=True)
def bfs_distances(nbr: np.ndarray, deg: np.ndarray, goals: np.ndarray) -> np.ndarray:
    """``(n, V)`` int32: each agent's number of moves from every vertex to its goal (a large number where it
    cannot reach it)."""
    nv = nbr.shape[0]
    n = goals.shape[0]
    dist = np.full((n, nv), _INF, dtype=np.int32)
    queue = np.empty(nv, dtype=np.int32)
    for a in range(n):
        head, tail = 0, 1
        queue[0] = goals[a]
        dist[a, goals[a]] = 0
        while head < tail:
            v = queue[head]
            head += 1
            for k in range(deg[v]):
                u = nbr[v, k]
                if dist[a, u] == _INF:
                    dist[a, u] = dist[a, v] + 1
                    queue[tail] = u
                    tail += 1
    return dist


@njit(cache=True)
def _grow1(a: np.ndarray, cap: int) -> np.ndarray:
    b = np.empty(cap, dtype=a.dtype)
    b[: a.shape[0]] = a
    return b


@njit(cache=True)
def _grow2(a: np.ndarray, cap: int) -> np.ndarray:
    b = np.empty((cap, a.shape[1]), dtype=a.dtype)
    b[: a.shape[0]] = a
    return b


@njit(cache=True)
def _hash(q: np.ndarray) -> np.uint64:
    h = np.uint64(1469598103934665603)
    for v in q:
        h ^= np.uint64(v + 1)
        h *= np.uint64(1099511628211)
    return h


@njit(cache=True)
def _slot(key: np.uint64, size: int) -> int:
    """The hash table slot of ``key`` in a table of ``size`` (a power of two) slots."""
    return np.int64(key & np.uint64(size - 1))


@njit(cache=True)
def _closes_cycle(first: int, home: int, q_from: np.ndarray, q_to: np.ndarray, occ_now: np.ndarray) -> bool:
    """Whether an agent standing at ``home`` that moves into the vertex agent ``first`` (already decided)
    leaves would close a rotation: the chain of decided agents each moving into the next one's vertex
    leads back to ``home``."""
    x = first
    for _ in range(q_from.shape[0] + 1):
        w = q_to[x]
        if w < 0 or w == q_from[x]:
            return False
        if w == home:
            return True
        y = occ_now[w]
        if y < 0:
            return False
        x = y
    return True


@njit(cache=True)
def _has_rotation(q_from: np.ndarray, q_to: np.ndarray, occ_now: np.ndarray, state: np.ndarray) -> bool:
    """Whether the transition ``q_from -> q_to`` moves agents along a cycle (``state``: scratch ``(n,)``)."""
    n = q_from.shape[0]
    state[:] = 0
    for a in range(n):
        if state[a] != 0:
            continue
        x = a
        found = False
        while True:
            if state[x] == 1:
                found = True
                break
            if state[x] == 2:
                break
            state[x] = 1
            w = q_to[x]
            if w == q_from[x]:
                break
            y = occ_now[w]
            if y < 0:
                break
            x = y
        x = a  # mark the walked chain done
        while state[x] == 1:
            state[x] = 2
            w = q_to[x]
            if w == q_from[x]:
                break
            y = occ_now[w]
            if y < 0:
                break
            x = y
        if found:
            return True
    return False


@njit(cache=True)
def _pull_room(nbr: np.ndarray, deg: np.ndarray, u: int, pusher_at: int, occ_now: np.ndarray,
               goals: np.ndarray) -> tuple:
    """How many ways on from ``u`` (a pusher standing at ``pusher_at``) there are for an agent that is pulled
    there (dead ends held by an agent at its goal do not count), and the last of them."""
    room = deg[u]
    last = -1
    for k in range(deg[u]):
        w = nbr[u, k]
        a = occ_now[w]
        if w == pusher_at or (deg[w] == 1 and a >= 0 and goals[a] == w):
            room -= 1
        else:
            last = w
    return room, last


@njit(cache=True)
def _swap_required(pusher: int, puller: int, v_pusher: int, v_puller: int, nbr: np.ndarray, deg: np.ndarray,
                   dist: np.ndarray, occ_now: np.ndarray, goals: np.ndarray) -> bool:
    """Whether ``pusher`` (at ``v_pusher``) and ``puller`` (at ``v_puller``) must pass each other: walking the
    corridor ahead of the pusher, no vertex offers room before the pusher stops getting closer to its goal,
    and each agent wants the other's side."""
    p, q = v_pusher, v_puller
    for _ in range(nbr.shape[0]):
        if dist[pusher, q] >= dist[pusher, p]:
            break
        room, last = _pull_room(nbr, deg, q, p, occ_now, goals)
        if room >= 2:
            return False
        if room <= 0:
            break
        p, q = q, last
    return dist[puller, p] < dist[puller, q] and (dist[pusher, p] == 0 or dist[pusher, q] < dist[pusher, p])


@njit(cache=True)
def _swap_possible(v_pusher: int, v_puller: int, nbr: np.ndarray, deg: np.ndarray, occ_now: np.ndarray,
                   goals: np.ndarray) -> bool:
    """Whether pulling along the corridor from ``v_puller`` (away from ``v_pusher``) reaches a vertex with
    room for the two agents to swap."""
    origin = v_pusher
    p, q = v_pusher, v_puller
    for _ in range(nbr.shape[0]):
        if q == origin:
            return False
        room, last = _pull_room(nbr, deg, q, p, occ_now, goals)
        if room >= 2:
            return True
        if room <= 0:
            return False
        p, q = q, last
    return False


@njit(cache=True)
def _swap_partner(i: int, q_from: np.ndarray, q_to: np.ndarray, cand: np.ndarray, nbr: np.ndarray,
                  deg: np.ndarray, dist: np.ndarray, occ_now: np.ndarray, goals: np.ndarray) -> int:
    """The agent agent ``i`` should pull along instead of pushing (the swap operation), or -1."""
    best = cand[i, 0]
    j = occ_now[best]
    if j >= 0 and j != i and q_to[j] < 0 and _swap_required(i, j, q_from[i], q_from[j], nbr, deg, dist, occ_now,
                                                            goals) \
            and _swap_possible(q_from[j], q_from[i], nbr, deg, occ_now, goals):
        return j
    if best != q_from[i]:  # clearing the way for a neighbour that must pass i
        v = q_from[i]
        for k in range(deg[v]):
            a = occ_now[nbr[v, k]]
            if a >= 0 and best != q_from[a] and _swap_required(a, i, v, best, nbr, deg, dist, occ_now, goals) \
                    and _swap_possible(best, v, nbr, deg, occ_now, goals):
                return a
    return -1


@njit(cache=True)
def _pibt(i: int, q_from: np.ndarray, q_to: np.ndarray, occ_now: np.ndarray, occ_next: np.ndarray,
          nbr: np.ndarray, deg: np.ndarray, dist: np.ndarray, goals: np.ndarray, tie: np.ndarray,
          cand: np.ndarray, swap: bool, rotations: bool) -> bool:
    """PIBT for agent ``i``: reserve its next vertex in ``q_to``/``occ_next``, pushing (planning first) the
    agent that stands there; False when it found none and stays."""
    v = q_from[i]
    kk = deg[v]
    for k in range(kk):
        u = nbr[v, k]
        cand[i, k] = u
        tie[u] = np.random.random()
    cand[i, kk] = v
    tie[v] = np.random.random()
    for a in range(1, kk + 1):  # insertion sort by distance to the goal, ties at random
        x = cand[i, a]
        key = dist[i, x] + tie[x]
        b = a - 1
        while b >= 0 and dist[i, cand[i, b]] + tie[cand[i, b]] > key:
            cand[i, b + 1] = cand[i, b]
            b -= 1
        cand[i, b + 1] = x
    partner = -1
    if swap:
        partner = _swap_partner(i, q_from, q_to, cand, nbr, deg, dist, occ_now, goals)
        if partner >= 0:
            for a in range((kk + 1) // 2):
                x = cand[i, a]
                cand[i, a] = cand[i, kk - a]
                cand[i, kk - a] = x
    for k in range(kk + 1):
        u = cand[i, k]
        if occ_next[u] >= 0:
            continue  # vertex conflict
        j = occ_now[u]
        if j >= 0 and j != i and q_to[j] == v:
            continue  # swap conflict
        if not rotations and j >= 0 and j != i and q_to[j] >= 0 and _closes_cycle(j, v, q_from, q_to, occ_now):
            continue
        occ_next[u] = i
        q_to[i] = u
        if j >= 0 and u != v and q_to[j] < 0:
            if not _pibt(j, q_from, q_to, occ_now, occ_next, nbr, deg, dist, goals, tie, cand, swap, rotations):
                continue
        if swap and k == 0 and partner >= 0 and q_to[partner] < 0 and occ_next[v] < 0:
            if rotations or not _closes_cycle(i, q_from[partner], q_from, q_to, occ_now):
                occ_next[v] = partner  # pull the partner into the vertex i leaves
                q_to[partner] = v
        return True
    occ_next[v] = i
    q_to[i] = v
    return False


@njit(cache=True)
def _edge_cost(a: np.ndarray, b: np.ndarray, goals: np.ndarray) -> int:
    """Sum of loss of the transition ``a -> b``: agents that are not at their goal before and after."""
    c = 0
    for k in range(goals.shape[0]):
        if a[k] != goals[k] or b[k] != goals[k]:
            c += 1
    return c


@njit(cache=True)
def transitions_valid(configs: np.ndarray, nbr: np.ndarray, deg: np.ndarray, rotations: bool) -> int:
    """The first step ``t`` (1-based) of ``configs`` ``(T, n)`` whose transition from step ``t - 1`` is not a
    valid MAPF move (an agent jumps, two share a vertex, two swap, or -- ``rotations`` False -- agents
    rotate), or 0 when every one is."""
    nv = nbr.shape[0]
    n = configs.shape[1]
    occ_now = np.full(nv, -1, dtype=np.int32)
    seen = np.full(nv, -1, dtype=np.int32)
    state = np.zeros(n, dtype=np.int32)
    for t in range(1, configs.shape[0]):
        a, b = configs[t - 1], configs[t]
        bad = False
        for k in range(n):
            occ_now[a[k]] = k
        for k in range(n):
            if seen[b[k]] == t:
                bad = True
            seen[b[k]] = t
            if a[k] != b[k]:
                near = False
                for m in range(deg[a[k]]):
                    if nbr[a[k], m] == b[k]:
                        near = True
                if not near:
                    bad = True
                j = occ_now[b[k]]
                if j >= 0 and b[j] == a[k]:
                    bad = True
        if not bad and not rotations and _has_rotation(a, b, occ_now, state):
            bad = True
        for k in range(n):
            occ_now[a[k]] = -1
        if bad:
            return t
    return 0


@njit(cache=True)
def lacam(nbr: np.ndarray, deg: np.ndarray, starts: np.ndarray, goals: np.ndarray, dist: np.ndarray, seed: int,
          time_limit_s: float, max_iterations: int, refine_iterations: int, swap: bool, rotations: bool) -> tuple:
    """LaCAM* from ``starts`` to ``goals`` (vertex ids ``(n,)``) on the graph ``nbr``/``deg`` with the agents'
    goal distances ``dist`` ``(n, V)`` (:func:`bfs_distances`).

    Stops at the first solution plus ``refine_iterations`` iterations of refinement, after
    ``max_iterations`` iterations in all (0: no limit), after ``time_limit_s`` (s) of wall time, or when the
    search space is exhausted.  Returns ``(status, configs (T + 1, n) int32, stats int64 (6,))``: status
    :data:`SOLVED` (configs from start to goal), :data:`UNSOLVABLE` (no solution exists: every reachable
    configuration was explored) or :data:`BUDGET` (none found within the budget); stats are iterations,
    high-level nodes, low-level nodes, the iteration of the first solution, its cost (sum of loss) and 1
    when the solution returned is proven optimal for the sum of loss (the search space exhausted)."""
    np.random.seed(seed)
    n = starts.shape[0]
    nv = nbr.shape[0]
    t0 = _now()
    # high-level nodes
    hcap = 256
    cfg = np.empty((hcap, n), dtype=np.int32)
    prio = np.empty((hcap, n), dtype=np.float64)
    order = np.empty((hcap, n), dtype=np.int32)
    parent = np.empty(hcap, dtype=np.int32)
    gval = np.empty(hcap, dtype=np.int64)
    hval = np.empty(hcap, dtype=np.int64)
    hkey = np.empty(hcap, dtype=np.uint64)
    ll_head = np.empty(hcap, dtype=np.int32)
    ll_tail = np.empty(hcap, dtype=np.int32)
    e_first = np.empty(hcap, dtype=np.int32)
    nh = 0
    # edges of the explored graph (linked lists per node)
    ecap = 1024
    e_to = np.empty(ecap, dtype=np.int32)
    e_next = np.empty(ecap, dtype=np.int32)
    ne = 0
    # low-level nodes: one constraint each, chained to the root by parent
    lcap = 1024
    l_parent = np.empty(lcap, dtype=np.int32)
    l_who = np.empty(lcap, dtype=np.int32)
    l_where = np.empty(lcap, dtype=np.int32)
    l_depth = np.empty(lcap, dtype=np.int32)
    l_next = np.empty(lcap, dtype=np.int32)
    nl = 0
    # configuration -> node: open addressing
    tcap = 1024
    table = np.full(tcap, -1, dtype=np.int32)
    # the open stack (may hold a node several times)
    ocap = 1024
    open_ = np.empty(ocap, dtype=np.int32)
    no = 0
    # PIBT's scratch
    occ_now = np.full(nv, -1, dtype=np.int32)
    occ_next = np.full(nv, -1, dtype=np.int32)
    q_to = np.full(n, -1, dtype=np.int32)
    tie = np.zeros(nv, dtype=np.float64)
    cand = np.empty((n, 5), dtype=np.int32)
    state = np.zeros(n, dtype=np.int32)
    choice = np.empty(5, dtype=np.int32)
    queue = np.empty(64, dtype=np.int32)
    goal_key = _hash(goals)
    stats = np.zeros(6, dtype=np.int64)
    stats[3] = -1
    stats[4] = -1

    # the start node
    cfg[0] = starts
    hsum = 0
    for a in range(n):
        hsum += dist[a, starts[a]]
        prio[0, a] = dist[a, starts[a]] / 10000.0
    order[0] = np.argsort(-prio[0], kind="mergesort").astype(np.int32)
    parent[0] = -1
    gval[0] = 0
    hval[0] = hsum
    hkey[0] = _hash(starts)
    l_parent[0] = -1
    l_who[0] = -1
    l_where[0] = -1
    l_depth[0] = 0
    l_next[0] = -1
    nl = 1
    ll_head[0] = 0
    ll_tail[0] = 0
    e_first[0] = -1
    nh = 1
    table[_slot(hkey[0], tcap)] = 0
    open_[0] = 0
    no = 1

    goal = -1
    status = BUDGET
    it = 0
    refined = 0
    while no > 0:
        it += 1
        if (it & 255) == 0:
            if _now() - t0 > time_limit_s:
                break
        if max_iterations > 0 and it > max_iterations:
            break
        if goal >= 0:
            refined += 1
            if refined > refine_iterations:
                break
        hnode = open_[no - 1]
        if goal >= 0 and gval[hnode] + hval[hnode] >= gval[goal]:
            no -= 1  # cannot improve on the solution
            continue
        if goal < 0 and hkey[hnode] == goal_key:
            same = True
            for a in range(n):
                if cfg[hnode, a] != goals[a]:
                    same = False
                    break
            if same:
                goal = hnode
                stats[3] = it
                stats[4] = gval[hnode]
                if refine_iterations <= 0:
                    break
                continue
        # the low-level search: the next constraint set of this node, and its children
        lnode = ll_head[hnode]
        if lnode < 0:
            no -= 1
            continue
        ll_head[hnode] = l_next[lnode]
        if ll_head[hnode] < 0:
            ll_tail[hnode] = -1
        depth = l_depth[lnode]
        if depth < n:
            a = order[hnode, depth]
            v = cfg[hnode, a]
            m = deg[v] + 1
            for k in range(deg[v]):
                choice[k] = nbr[v, k]
            choice[deg[v]] = v
            for k in range(m - 1, 0, -1):  # shuffle
                r = np.random.randint(0, k + 1)
                x = choice[k]
                choice[k] = choice[r]
                choice[r] = x
            if nl + m > lcap:
                lcap = 2 * lcap + m
                l_parent = _grow1(l_parent, lcap)
                l_who = _grow1(l_who, lcap)
                l_where = _grow1(l_where, lcap)
                l_depth = _grow1(l_depth, lcap)
                l_next = _grow1(l_next, lcap)
            for k in range(m):
                c = nl
                nl += 1
                l_parent[c] = lnode
                l_who[c] = a
                l_where[c] = choice[k]
                l_depth[c] = depth + 1
                l_next[c] = -1
                if ll_tail[hnode] < 0:
                    ll_head[hnode] = c
                else:
                    l_next[ll_tail[hnode]] = c
                ll_tail[hnode] = c
        # a successor configuration that meets the constraints (PIBT does the rest)
        q_from = cfg[hnode]
        for a in range(n):
            occ_now[q_from[a]] = a
            q_to[a] = -1
        ok = True
        c = lnode
        while l_depth[c] > 0:
            q_to[l_who[c]] = l_where[c]
            c = l_parent[c]
        for a in range(n):
            u = q_to[a]
            if u < 0:
                continue
            if occ_next[u] >= 0:
                ok = False
                break
            j = occ_now[u]
            if j >= 0 and j != a and q_to[j] == q_from[a]:
                ok = False
                break
            occ_next[u] = a
        if ok:
            for k in range(n):
                a = order[hnode, k]
                if q_to[a] < 0 and not _pibt(a, q_from, q_to, occ_now, occ_next, nbr, deg, dist, goals, tie, cand,
                                             swap, rotations):
                    ok = False
                    break
        if ok and not rotations and _has_rotation(q_from, q_to, occ_now, state):
            ok = False
        for a in range(n):
            occ_now[q_from[a]] = -1
            if q_to[a] >= 0:
                occ_next[q_to[a]] = -1
        if not ok:
            continue
        # known configuration, or a new node
        key = _hash(q_to)
        slot = _slot(key, tcap)
        found = -1
        while table[slot] >= 0:
            x = table[slot]
            if hkey[x] == key:
                same = True
                for a in range(n):
                    if cfg[x, a] != q_to[a]:
                        same = False
                        break
                if same:
                    found = x
                    break
            slot = (slot + 1) & (tcap - 1)
        if no + 2 > ocap:
            ocap *= 2
            open_ = _grow1(open_, ocap)
        if found >= 0:
            # rewrite: the edge, then costs relaxed over the explored graph
            dup = False
            e = e_first[hnode]
            while e >= 0:
                if e_to[e] == found:
                    dup = True
                    break
                e = e_next[e]
            if not dup:
                if ne + 1 > ecap:
                    ecap *= 2
                    e_to = _grow1(e_to, ecap)
                    e_next = _grow1(e_next, ecap)
                e_to[ne] = found
                e_next[ne] = e_first[hnode]
                e_first[hnode] = ne
                ne += 1
            head, tail = 0, 1
            queue[0] = hnode
            while head != tail:
                f = queue[head]
                head += 1
                e = e_first[f]
                while e >= 0:
                    t = e_to[e]
                    gv = gval[f] + _edge_cost(cfg[f], cfg[t], goals)
                    if gv < gval[t]:
                        gval[t] = gv
                        parent[t] = f
                        if tail + 1 > queue.shape[0]:
                            if head > 0:  # compact the queue
                                queue[: tail - head] = queue[head:tail].copy()
                                tail -= head
                                head = 0
                            if tail + 1 > queue.shape[0]:
                                queue = _grow1(queue, 2 * queue.shape[0])
                        queue[tail] = t
                        tail += 1
                        if goal >= 0 and gv + hval[t] < gval[goal]:
                            if no + 1 > ocap:
                                ocap *= 2
                                open_ = _grow1(open_, ocap)
                            open_[no] = t
                            no += 1
                    e = e_next[e]
            if goal >= 0 and np.random.random() < _RESTART:
                open_[no] = 0
            else:
                open_[no] = found
            no += 1
            continue
        if nh + 1 > hcap:
            hcap *= 2
            cfg = _grow2(cfg, hcap)
            prio = _grow2(prio, hcap)
            order = _grow2(order, hcap)
            parent = _grow1(parent, hcap)
            gval = _grow1(gval, hcap)
            hval = _grow1(hval, hcap)
            hkey = _grow1(hkey, hcap)
            ll_head = _grow1(ll_head, hcap)
            ll_tail = _grow1(ll_tail, hcap)
            e_first = _grow1(e_first, hcap)
        new = nh
        nh += 1
        cfg[new] = q_to
        hsum = 0
        for a in range(n):
            d = dist[a, q_to[a]]
            hsum += d
            if d != 0:
                prio[new, a] = prio[hnode, a] + 1.0
            else:
                prio[new, a] = prio[hnode, a] - np.floor(prio[hnode, a])
        order[new] = np.argsort(-prio[new], kind="mergesort").astype(np.int32)
        parent[new] = hnode
        gval[new] = gval[hnode] + _edge_cost(q_from, q_to, goals)
        hval[new] = hsum
        hkey[new] = key
        if nl + 1 > lcap:
            lcap *= 2
            l_parent = _grow1(l_parent, lcap)
            l_who = _grow1(l_who, lcap)
            l_where = _grow1(l_where, lcap)
            l_depth = _grow1(l_depth, lcap)
            l_next = _grow1(l_next, lcap)
        l_parent[nl] = -1
        l_who[nl] = -1
        l_where[nl] = -1
        l_depth[nl] = 0
        l_next[nl] = -1
        ll_head[new] = nl
        ll_tail[new] = nl
        nl += 1
        if ne + 2 > ecap:
            ecap *= 2
            e_to = _grow1(e_to, ecap)
            e_next = _grow1(e_next, ecap)
        e_to[ne] = new  # both directions
        e_next[ne] = e_first[hnode]
        e_first[hnode] = ne
        e_to[ne + 1] = hnode
        e_next[ne + 1] = -1
        e_first[new] = ne + 1
        ne += 2
        table[slot] = new
        if 2 * nh > tcap:  # rehash
            tcap *= 4
            table = np.full(tcap, -1, dtype=np.int32)
            for x in range(nh):
                s = _slot(hkey[x], tcap)
                while table[s] >= 0:
                    s = (s + 1) & (tcap - 1)
                table[s] = x
        open_[no] = new
        no += 1
    stats[0] = it
    stats[1] = nh
    stats[2] = nl
    if goal >= 0:
        status = SOLVED
        stats[5] = 1 if no == 0 else 0
        length = 0
        x = goal
        while x >= 0:
            length += 1
            x = parent[x]
        out = np.empty((length, n), dtype=np.int32)
        x = goal
        for t in range(length - 1, -1, -1):
            out[t] = cfg[x]
            x = parent[x]
        return status, out, stats
    if no == 0:
        status = UNSOLVABLE
    return status, np.empty((0, n), dtype=np.int32), stats


@njit(cache=True)
def _heap_push(key: np.ndarray, val: np.ndarray, size: int, k: int, v: int) -> int:
    i = size
    key[i] = k
    val[i] = v
    while i > 0:
        p = (i - 1) // 2
        if key[p] <= key[i]:
            break
        key[p], key[i] = key[i], key[p]
        val[p], val[i] = val[i], val[p]
        i = p
    return size + 1


@njit(cache=True)
def _heap_pop(key: np.ndarray, val: np.ndarray, size: int) -> int:
    size -= 1
    key[0] = key[size]
    val[0] = val[size]
    i = 0
    while True:
        a, b, m = 2 * i + 1, 2 * i + 2, i
        if a < size and key[a] < key[m]:
            m = a
        if b < size and key[b] < key[m]:
            m = b
        if m == i:
            break
        key[m], key[i] = key[i], key[m]
        val[m], val[i] = val[i], val[m]
        i = m
    return size


@njit(cache=True)
def prioritized_grid(nbr: np.ndarray, deg: np.ndarray, starts: np.ndarray, goals: np.ndarray, dist: np.ndarray,
                     horizon: int, time_limit_s: float) -> tuple:
    """Prioritized planning on the graph, the baseline of ``bench/mapf.py``: agents in index order, each the
    earliest path (space-time A* with waits, the goal distance as heuristic) that avoids the vertices and edges
    of the agents before it, which then stand at their goals for good (an agent may arrive only once no
    earlier agent passes its goal later).  ``horizon``: the last time step searched.  Returns ``(status,
    configs (T + 1, n), agent)``: :data:`SOLVED`, or :data:`UNSOLVABLE` with the first agent that found no
    path (prioritized planning is incomplete: another order may work), or :data:`BUDGET` past
    ``time_limit_s`` (s)."""
    t0 = _now()
    n = starts.shape[0]
    nv = nbr.shape[0]
    occ = np.full((horizon + 1, nv), -1, dtype=np.int32)
    park = np.full(nv, horizon + 1, dtype=np.int64)
    last = np.full(nv, -1, dtype=np.int64)
    closed = np.zeros((horizon + 1, nv), dtype=np.int32)
    seen = np.zeros((horizon + 1, nv), dtype=np.int32)
    back = np.empty((horizon + 1, nv), dtype=np.int32)
    cap = 1 << 16
    hkey = np.empty(cap, dtype=np.int64)
    hval = np.empty(cap, dtype=np.int64)
    arrive = np.zeros(n, dtype=np.int64)
    route = np.empty(horizon + 1, dtype=np.int32)
    pops = 0
    for a in range(n):
        gen = a + 1
        size = _heap_push(hkey, hval, 0, dist[a, starts[a]] * (horizon + 2), starts[a])
        seen[0, starts[a]] = gen
        found = -1
        while size > 0:
            pops += 1
            if (pops & 1023) == 0 and _now() - t0 > time_limit_s:
                return BUDGET, np.empty((0, n), dtype=np.int32), a
            state = hval[0]
            size = _heap_pop(hkey, hval, size)
            t, v = state // nv, state % nv
            if closed[t, v] == gen:
                continue
            closed[t, v] = gen
            if v == goals[a] and t > last[v]:
                found = t
                break
            if t == horizon:
                continue
            tn = t + 1
            for k in range(deg[v] + 1):
                u = nbr[v, k] if k < deg[v] else v
                if occ[tn, u] >= 0 or park[u] <= tn or closed[tn, u] == gen or seen[tn, u] == gen:
                    continue
                b = occ[t, u]
                if b >= 0 and u != v and occ[tn, v] == b:
                    continue  # b moves u -> v while we move v -> u
                seen[tn, u] = gen
                back[tn, u] = v
                if size + 1 > hkey.shape[0]:
                    hkey = _grow1(hkey, 2 * hkey.shape[0])
                    hval = _grow1(hval, 2 * hval.shape[0])
                size = _heap_push(hkey, hval, size, (tn + dist[a, u]) * (horizon + 2) - tn, tn * nv + u)
        if found < 0:
            return UNSOLVABLE, np.empty((0, n), dtype=np.int32), a
        v = goals[a]
        for t in range(found, -1, -1):
            route[t] = v
            if t > 0:
                v = back[t, v]
        for t in range(found + 1):
            occ[t, route[t]] = a
            if route[t] != goals[a] or t < found:
                last[route[t]] = max(last[route[t]], t)
        park[goals[a]] = found
        arrive[a] = found
    span = int(arrive.max()) if n else 0
    out = np.empty((span + 1, n), dtype=np.int32)
    for t in range(span + 1):
        for a in range(n):
            out[t, a] = goals[a] if t >= arrive[a] else -1
    for t in range(span + 1):
        for v in range(nv):
            a = occ[t, v]
            if a >= 0 and t <= arrive[a]:
                out[t, a] = v
    return SOLVED, out, -1
