// Capture of sharp edges by a quad mesh lying on a surface: where a sharp edge of the surface (a
// crease of a CAD part) is followed by no edge of the quad mesh, the nearest path of quad edges is
// moved onto it. A polycube edge can only follow a crease that runs between two charts from
// corner to corner; creases that fade out inside a face (fandisk), or that the layout missed, are
// otherwise cut by the quads and dominate the Hausdorff distance.
#pragma once
#include <map>
#include <vector>

#include "polycube/core/types.h"
#include "polycube/geometry/closest_point.h"

namespace polycube::geometry {

/// Chains of sharp edges of s (`sharp` as from sharp_edges; open edges are left out): polylines of
/// vertex ids split at vertices with other than two sharp edges. A closed loop repeats its first
/// vertex at the end.
std::vector<std::vector<int>> sharp_chains(const SurfaceMesh& s, const std::vector<unsigned char>& sharp);

/// Arc-length positions along the chains of sharp edges (sharp_chains): tells whether two points on
/// sharp edges lie on one chain and how far apart along it. Two quad vertices joined by an edge
/// that cuts a bend of their sharp edge (fandisk: 22.5 degrees where a soft crease meets it) are
/// neighbours along that edge although the quad edge's midpoint is off it.
class SharpChainPositions {
 public:
  /// s and sharp (as from sharp_edges) are kept by reference: they must outlive this object.
  SharpChainPositions(const SurfaceMesh& s, const std::vector<unsigned char>& sharp);
  struct Position {
    int chain = -1;
    double s = 0;  ///< arc length from the chain's first vertex
  };
  /// The position of the point of a sharp edge nearest p among the triangles around p's closest
  /// point on s (tree: over s; adj: face_adjacency(s.F)), if it lies within tol.
  bool locate(const TriangleTree& tree, const MatX3i& adj, const Vec3& p, double tol, Position& out) const;
  /// Arc length between two positions of one chain (the shorter way round a closed loop); infinity
  /// for positions on different chains.
  double distance(const Position& a, const Position& b) const;

 private:
  const SurfaceMesh& s_;
  const std::vector<unsigned char>& sharp_;
  std::vector<double> length_;      ///< per chain
  std::vector<char> closed_;        ///< per chain
  struct EdgeAt {
    int chain;
    double s_from;  ///< arc length at the edge's first vertex along the chain
    int from;       ///< that vertex
  };
  std::map<std::pair<int, int>, EdgeAt> edges_;  ///< sorted vertex pair -> place on its chain
};

/// Creases of s: the sharp edges (sharp_edges bitmask, open edges left out) of the chains of edges
/// sharper than `weak_deg` that have at least one edge sharper than `strong_deg`. A crease of a CAD
/// part that fades out keeps its weak end; the facets of a coarse smooth surface (all weak) go.
std::vector<unsigned char> crease_edges(const SurfaceMesh& s, double weak_deg, double strong_deg);

struct FeatureCaptureOptions {
  /// A crease point is followed when a mesh edge along the crease (within 45 degrees) passes within
  /// this x edge length.
  double cover_tolerance = 0.1;
  double corridor = 1.2;        ///< vertices move onto a crease only from within this x edge length of it
  double min_run = 0.75;         ///< runs of unfollowed crease shorter than this x edge length are left
};

struct FeatureCaptureStats {
  int runs = 0;        ///< runs of crease followed by no mesh edge
  int captured = 0;    ///< of those, runs a path of mesh edges was moved onto
  int moved = 0;       ///< vertices moved onto creases
  struct Run {
    std::vector<int> vertices;  ///< the mesh vertices moved onto the crease
    std::vector<Vec3> crease;   ///< points along the run of crease
  };
  std::vector<Run> captured_runs;
};

/// Moves paths of edges of the quad mesh (V, Q), which lies on s, onto the chains of s that none
/// of its edges follows (within cover_tolerance x elen, elen: the mean quad edge length). A path
/// runs between the mesh vertices nearest the ends of an unfollowed run, through vertices within
/// `corridor` x elen of it, each vertex moved to its closest point on the run in order along it.
/// `locked` vertices (may be empty) never move. The caller judges the captures (captured_runs)
/// after relaxing their neighbourhood and undoes the poor ones. `snapped` (resized to V.rows())
/// flags the moved vertices.
FeatureCaptureStats capture_sharp_edges(MatX3d& V, const MatX4i& Q, const SurfaceMesh& s,
                                        const std::vector<unsigned char>& sharp, const std::vector<char>& locked,
                                        std::vector<char>& snapped, const FeatureCaptureOptions& opt = {});

/// How well the edges of the quad mesh (V, Q) follow the chains of sharp edges of s.
struct CreaseCoverage {
  double max_gap = 0;   ///< largest distance of a crease point to the quad edges along it (at most 2 x elen)
  double followed = 1;  ///< fraction of crease points within tolerance x elen of a quad edge along it
};
CreaseCoverage crease_coverage(const MatX3d& V, const MatX4i& Q, const SurfaceMesh& s,
                               const std::vector<unsigned char>& sharp, double tolerance = 0.1);

}  // namespace polycube::geometry
