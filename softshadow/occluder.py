"""The occluder's topology and its silhouette under the sun (NumPy, discrete).

An ``Occluder`` holds a cleaned triangle mesh in its own frame and its edge
table, built once. ``silhouette`` picks, for a given (concrete) pose and light
direction, the edges where the mesh folds away from the light:

- edges shared by a lit face (n . L < -tol) and a face that is not lit, and
- boundary edges of open meshes (one face),

and returns for each the data the differentiable part needs: its two vertex
indices, the sign that makes its normal point out of the shadow volume, and
the seed's per-edge normal N = normalize(N1 + N2) for the ``paper`` rule.
Faces within ``tol`` of parallel to the light count as not lit; their own
shadow is a line of zero area, so the hard shadow does not depend on the tie.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import trimesh

from .meshes import clean_mesh

__all__ = ["Occluder", "Silhouette", "silhouette", "merge_collinear"]

PARALLEL_TOL = 1e-7   # |n . L| below this: a face seen exactly edge-on from the sun
PARALLEL_EDGE_TOL = 1e-6  # |t x L| below this: an edge along the light projects to a point
COLLINEAR_TOL = 1e-9  # ||t1 . t2| - 1| below this: two edges are collinear (merge_collinear)


@dataclasses.dataclass(frozen=True, eq=False)
class Occluder:
    """A mesh ready for shadow casting (mesh frame, metres).

    vertices (V, 3); faces (F, 3); face_normals (F, 3) unit; edges (E, 2)
    sorted vertex pairs; edge_faces (E, M) face indices padded with -1;
    watertight: closed and consistently oriented (every edge has two faces running
    along it in opposite directions), so the lit faces alone make the hard shadow.
    """

    vertices: np.ndarray
    faces: np.ndarray
    face_normals: np.ndarray
    edges: np.ndarray
    edge_faces: np.ndarray
    face_edge_index: np.ndarray
    face_edge_dir: np.ndarray
    watertight: bool

    @classmethod
    def from_trimesh(cls, mesh: trimesh.Trimesh, source: str = "mesh") -> "Occluder":
        mesh = clean_mesh(mesh, source)
        v = np.asarray(mesh.vertices, dtype=np.float64)
        f = np.asarray(mesh.faces, dtype=np.int64)
        tri = v[f]
        normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        directed = np.stack([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]], 1).reshape(-1, 2)
        face_edges = np.sort(directed, axis=1)
        face_dir = np.where(directed[:, 0] == face_edges[:, 0], 1, -1).reshape(-1, 3)
        edges, inverse, counts = np.unique(face_edges, axis=0, return_inverse=True, return_counts=True)
        inverse = inverse.ravel()
        order = np.argsort(inverse, kind="stable")
        face_of = order // 3
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        width = int(counts.max())
        edge_faces = -np.ones((len(edges), width), dtype=np.int64)
        slot = np.arange(len(order)) - np.repeat(starts, counts)
        edge_faces[inverse[order], slot] = face_of
        net = np.bincount(inverse, weights=face_dir.ravel(), minlength=len(edges))
        closed_oriented = bool(np.all(counts == 2) and not np.any(net))
        return cls(v, f, normals, edges, edge_faces, inverse.reshape(-1, 3), face_dir, closed_oriented)

    @property
    def n_faces(self) -> int:
        return len(self.faces)

    @functools.cached_property
    def two_faced(self) -> bool:
        """Every edge has exactly two faces (a closed mesh, not necessarily oriented)."""
        return self.edge_faces.shape[1] == 2 and bool(np.all(self.edge_faces >= 0))

    @functools.cached_property
    def twin_edges(self) -> np.ndarray:
        """(P, 2) pairs of distinct edges with the same two end points (vertices at equal
        positions): where a pinched surface was split (``lod.split_pinched``). Usually empty."""
        positions, position = np.unique(self.vertices, axis=0, return_inverse=True)
        if len(positions) == len(self.vertices):
            return np.zeros((0, 2), np.int64)  # no two vertices at one position
        ends = np.sort(position.reshape(-1)[self.edges], axis=1)
        order = np.lexsort((ends[:, 1], ends[:, 0]))
        same = np.flatnonzero(np.all(ends[order[1:]] == ends[order[:-1]], axis=1))
        return np.stack([order[same], order[same + 1]], 1).astype(np.int64)

    @functools.cached_property
    def edge_tangent(self) -> np.ndarray:
        """(E, 3) unit direction of each edge, from its first to its second vertex (mesh frame)."""
        t = self.vertices[self.edges[:, 1]] - self.vertices[self.edges[:, 0]]
        return t / np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-300)

    @functools.cached_property
    def edge_inward(self) -> np.ndarray:
        """(E, M, 3) each slot's face centroid minus the edge's midpoint (mesh frame; 0 in padding)."""
        centroid = self.vertices[self.faces].mean(1)
        mid = 0.5 * (self.vertices[self.edges[:, 0]] + self.vertices[self.edges[:, 1]])
        out = centroid[np.maximum(self.edge_faces, 0)] - mid[:, None, :]
        return np.where((self.edge_faces >= 0)[..., None], out, 0.0)

    @functools.cached_property
    def edge_paper_normal(self) -> np.ndarray:
        """(E, 3) the seed's normal normalize(N1 + N2) of a two-faced edge (mesh frame)."""
        ef = np.maximum(self.edge_faces[:, :2], 0)
        both = (self.edge_faces[:, 1] >= 0) & (ef[:, 1] != ef[:, 0])
        paper = self.face_normals[ef[:, 0]] + np.where(both[:, None], self.face_normals[ef[:, 1]], 0.0)
        return paper / np.maximum(np.linalg.norm(paper, axis=1, keepdims=True), 1e-12)

    @functools.cached_property
    def collinear_pairs(self) -> np.ndarray:
        """(P, 3) pairs of edges sharing a vertex and collinear within ``merge_collinear``'s
        tolerance, with that vertex: only these can ever merge, whatever the pose and sun."""
        vert = self.edges.ravel()
        edge = np.repeat(np.arange(len(self.edges)), 2)
        order = np.argsort(vert, kind="stable")
        vert, edge = vert[order], edge[order]
        t = self.edge_tangent
        found = []
        for shift in range(1, len(vert)):
            same = np.flatnonzero(vert[shift:] == vert[:-shift])
            if not len(same):
                break
            a, b = edge[same], edge[same + shift]
            hit = np.abs(np.abs(np.einsum("ij,ij->i", t[a], t[b])) - 1.0) < COLLINEAR_TOL
            found.append(np.stack([a[hit], b[hit], vert[same[hit]]], 1))
        return np.concatenate(found) if found else np.zeros((0, 3), np.int64)

    @functools.cached_property
    def edge_face_dir(self) -> np.ndarray:
        """(E, M) +-1: whether the face in each slot of ``edge_faces`` runs along the edge
        in its sorted vertex order (0 in padding slots)."""
        out = np.zeros(self.edge_faces.shape, np.int64)
        order = np.argsort(self.face_edge_index.ravel(), kind="stable")
        edge = self.face_edge_index.ravel()[order]
        starts = np.flatnonzero(np.r_[True, edge[1:] != edge[:-1]])
        slot = np.arange(len(order)) - np.repeat(starts, np.diff(np.r_[starts, len(order)]))
        out[edge, slot] = self.face_edge_dir.ravel()[order]
        return out


@dataclasses.dataclass(frozen=True)
class Silhouette:
    """Silhouette edges for one pose and light (world frame).

    vertex_ids (S, 2); outward_sign (S,) +-1 so that sign * (t x L) points out
    of the shadow volume; paper_normal_local (S, 3) normalize(N1 + N2) in the
    mesh frame; lit (F,) the lit-face mask used; fill_edges: for each layer of
    faces whose union is the hard shadow (the lit faces; for open meshes also the
    faces turned away), its boundary as (edges (B, 2) in sorted vertex order,
    winding weights (B,)): the net count of faces running along each edge;
    normal_local (S, 3): the outward normal sign * normalize(t x L) in the mesh frame;
    edge_index (S,): the mesh edge (``Occluder.edges``) of each, for a merged chain its first.
    """

    vertex_ids: np.ndarray
    outward_sign: np.ndarray
    paper_normal_local: np.ndarray
    lit: np.ndarray
    fill_edges: tuple[tuple[np.ndarray, np.ndarray], ...] = ()
    normal_local: np.ndarray | None = None
    edge_index: np.ndarray | None = None


def silhouette(occ: Occluder, world_vertices: np.ndarray, rotation: np.ndarray,
               light: np.ndarray) -> Silhouette:
    """Silhouette and boundary edges of the posed mesh under light direction ``light`` (3,).

    Directions are compared in the mesh frame (the light rotated into it), with the
    per-edge geometry cached on the occluder; a uniform positive scale changes none of them.
    """
    light = np.asarray(light, dtype=np.float64)
    rotation = np.asarray(rotation, dtype=np.float64)
    light_local = rotation.T @ light
    normals = occ.face_normals
    ndotl = normals @ light_local
    lit = ndotl < -PARALLEL_TOL
    ef = occ.edge_faces
    if occ.two_faced:
        lit0, lit1 = lit[ef[:, 0]], lit[ef[:, 1]]
        candidates = np.flatnonzero(lit0 != lit1)
    else:
        valid = ef >= 0
        lit_e = valid & lit[np.maximum(ef, 0)]
        n_valid = valid.sum(1)
        n_lit = lit_e.sum(1)
        candidates = np.flatnonzero(((n_lit > 0) & (n_lit < n_valid)) | (n_valid == 1))
    t = occ.edge_tangent[candidates]
    cvec = np.cross(t, light_local)
    c = np.sqrt(np.einsum("ij,ij->i", cvec, cvec))
    keep = c > PARALLEL_EDGE_TOL
    idx, t, cvec, c = candidates[keep], t[keep], cvec[keep], c[keep]
    # The face that is "the object" beside the edge, seen from the light: a lit face, or the only one.
    if occ.two_faced:  # one face lit, the other not: the seed's normal is the cached pair's
        inner_slot = (~lit[ef[idx, 0]]).astype(np.intp)
        paper = occ.edge_paper_normal[idx]
    else:
        ef_s = ef[idx]
        valid_s = ef_s >= 0
        lit_s = valid_s & lit[np.maximum(ef_s, 0)]
        rows = np.arange(len(idx))
        inner_slot = np.where(lit_s.any(1), np.argmax(lit_s, axis=1), 0)
        unlit_s = valid_s & ~lit_s
        other_slot = np.where(unlit_s.any(1), np.argmax(unlit_s, axis=1), inner_slot)
        inner_face, other_face = ef_s[rows, inner_slot], ef_s[rows, other_slot]
        paper = occ.face_normals[inner_face] + np.where((other_face != inner_face)[:, None],
                                                        occ.face_normals[other_face], 0.0)
        paper /= np.maximum(np.sqrt(np.einsum("ij,ij->i", paper, paper)), 1e-12)[:, None]
    n = cvec / c[:, None]
    # The inner face's centroid minus the edge's midpoint.
    inward = occ.edge_inward.reshape(-1, 3)[idx * occ.edge_inward.shape[1] + inner_slot]
    sign = np.where(np.einsum("ij,ij->i", n, inward) > 0, -1.0, 1.0)
    twins = occ.twin_edges
    if len(twins):
        # Two sheets of the surface meeting along one line (a pinch split into coincident edges),
        # both on the silhouette and facing opposite ways: the shadow lies on both sides of the
        # line, so neither edge bounds it (and the pixel arrangement would meet two coincident
        # segments).
        e1, e2, both = _on_silhouette(idx, len(occ.edges), twins)
        e1, e2 = e1[both], e2[both]
        opposite = np.einsum("ij,ij->i", sign[e1, None] * n[e1], sign[e2, None] * n[e2]) < 0
        drop = np.zeros(len(idx), bool)
        drop[e1[opposite]] = drop[e2[opposite]] = True
        if drop.any():
            idx, t, n, sign, paper = idx[~drop], t[~drop], n[~drop], sign[~drop], paper[~drop]
    ids = occ.edges[idx]
    normal = sign[:, None] * n
    edge_index = idx
    pairs = occ.collinear_pairs
    if len(pairs):
        # The mesh's collinear pairs with both edges on the silhouette, at a vertex no other
        # silhouette edge uses.
        e1, e2, both = _on_silhouette(idx, len(occ.edges), pairs)
        if both.any():
            degree = np.bincount(ids.ravel(), minlength=len(occ.vertices))
            both &= degree[pairs[:, 2]] == 2
            ids, sign, paper, lead = merge_collinear(ids, world_vertices, light, sign, paper,
                                                     tangent=t, normal=normal,
                                                     pairs=(e1[both], e2[both]), return_lead=True)
            normal = normal[lead]
            edge_index = idx[lead]
    layers = [lit] if occ.watertight else [lit, (~lit) & (np.abs(ndotl) > PARALLEL_TOL)]
    fill = []
    for faces in layers:
        if faces is lit and occ.watertight:
            # Closed and consistently oriented: exactly the edges with one lit face have a
            # non-zero net count, that face's direction along the edge.
            direction = occ.edge_face_dir[candidates]
            net = np.where(lit0[candidates], direction[:, 0], direction[:, 1])
            fill.append((occ.edges[candidates], net.astype(np.float64)))
            continue
        # Net count of the layer's faces running along each edge (their boundary, oriented).
        on = (ef >= 0) & faces[np.maximum(ef, 0)]
        net = np.where(on, occ.edge_face_dir, 0).sum(1)
        keep_e = np.flatnonzero(net)
        fill.append((occ.edges[keep_e], net[keep_e].astype(np.float64)))
    return Silhouette(ids, sign, paper, lit, tuple(fill), normal, edge_index)


def _on_silhouette(idx: np.ndarray, n_edges: int, pairs: np.ndarray):
    """For pairs (P, 2+) of mesh edges: each one's position among the silhouette's edges idx
    (mesh edge indices; -1: not on it), (P,) twice, and whether both are on it (P,)."""
    position = np.full(n_edges, -1, np.int64)
    position[idx] = np.arange(len(idx))
    e1, e2 = position[pairs[:, 0]], position[pairs[:, 1]]
    return e1, e2, (e1 >= 0) & (e2 >= 0)


def merge_collinear(ids: np.ndarray, world: np.ndarray, light: np.ndarray, sign: np.ndarray,
                    paper: np.ndarray, tol: float = COLLINEAR_TOL, tangent: np.ndarray | None = None,
                    normal: np.ndarray | None = None, pairs: tuple[np.ndarray, np.ndarray] | None = None,
                    return_lead: bool = False):
    """Join chains of collinear silhouette edges (a subdivided box edge) into single edges.

    Two edges meeting at a vertex used by no other silhouette edge are joined when they
    point the same way, face the same way and share the seed's normal. Fewer, longer edges
    make a plan hold over larger sun and pose moves, and cost less. ``tangent`` and
    ``normal`` (unit, outward), in any one frame, save recomputing them from ``world``;
    ``pairs`` (two index arrays into ``ids``), the edge pairs meeting at a vertex no other
    edge uses, if already known. With ``return_lead`` also returns, for each output edge,
    the input edge whose orientation, sign and normals it keeps.
    """
    if len(ids) < 2:
        return (ids, sign, paper, np.arange(len(ids))) if return_lead else (ids, sign, paper)
    if tangent is None or normal is None:
        tangent = world[ids[:, 1]] - world[ids[:, 0]]
        tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-300)
        normal = np.cross(tangent, light)
        normal = sign[:, None] * normal / np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    t, n = tangent, normal
    if pairs is None:
        flat = ids.ravel()
        order = np.argsort(flat, kind="stable")
        sorted_v = flat[order]
        starts = np.flatnonzero(np.r_[True, sorted_v[1:] != sorted_v[:-1]])
        counts = np.diff(np.r_[starts, len(flat)])
        pair = starts[counts == 2]
        e1, e2 = order[pair] // 2, order[pair + 1] // 2
    else:
        e1, e2 = pairs
    join = ((np.abs(np.abs(np.einsum("ij,ij->i", t[e1], t[e2])) - 1.0) < tol)
            & (np.einsum("ij,ij->i", n[e1], n[e2]) > 1.0 - tol)
            & (np.einsum("ij,ij->i", paper[e1], paper[e2]) > 1.0 - 1e-6))
    if not join.any():
        return (ids, sign, paper, np.arange(len(ids))) if return_lead else (ids, sign, paper)
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    m = len(ids)
    graph = coo_matrix((np.ones(int(join.sum())), (e1[join], e2[join])), shape=(m, m))
    _, roots = connected_components(graph, directed=False)
    # One output edge per chain, in the order of each chain's first member.
    _, first_member, inverse = np.unique(roots, return_index=True, return_inverse=True)
    order_out = np.argsort(first_member, kind="stable")
    lead = first_member[order_out]  # the chain's first member (its tangent's orientation is kept)
    rank = np.empty_like(order_out)
    rank[order_out] = np.arange(len(order_out))
    chain = rank[inverse.ravel()]  # output index of each input edge
    n_out = len(lead)
    # The chain's ends: its extreme vertices along the lead member's direction.
    lead_t = world[ids[lead, 1]] - world[ids[lead, 0]]  # the lead member's direction, world frame
    proj = np.einsum("ijk,ik->ij", world[ids], lead_t[chain])  # (m, 2)
    verts = ids.ravel()
    p = proj.ravel()
    owner = np.repeat(chain, 2)
    lo_order = np.lexsort((p, owner))
    first_of = np.flatnonzero(np.r_[True, owner[lo_order][1:] != owner[lo_order][:-1]])
    last_of = np.r_[first_of[1:] - 1, len(lo_order) - 1]
    out_ids = np.stack([verts[lo_order[first_of]], verts[lo_order[last_of]]], 1)
    single = np.bincount(chain, minlength=n_out) == 1
    out_ids[single] = ids[lead[single]]
    if return_lead:
        return out_ids, sign[lead], paper[lead], lead
    return out_ids, sign[lead], paper[lead]
