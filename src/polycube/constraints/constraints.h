// User control of the polycube (paper Section 3.2, Eqs. 12-13): edges of the input surface that
// should become polycube edges ("sharp": adjacent normals at a right angle) or lie inside a
// polycube face ("flat": adjacent normals equal), given explicitly, as regions, or detected.
//
// Constraint file (JSON), ids 0-based into the input as read (vertices in file order; triangles
// in file order, polygons fanned into triangles in order):
//   {"constraints": [
//      {"name": "rim", "type": "sharp", "weight": 100, "edges": [[12, 13], [13, 40]]},
//      {"type": "flat", "faces": [5, 6, 7, 8]},
//      {"type": "sharp", "faces": [100, 101]},
//      {"type": "flat", "group": "logo"}
//   ]}
// "edges": pairs of vertex ids joined by an edge of the surface. "faces": a region (or "group": the
// triangles of a painted region of the input, see MeshData::face_group); a flat region
// constrains every edge inside it (the region becomes part of one polycube face), a sharp region
// every edge of its border (the border becomes polycube edges). "weight" (omega, optional)
// defaults to ConstraintOptions::weight.
#pragma once
#include <array>
#include <string>
#include <vector>

#include "polycube/core/types.h"
#include "polycube/deform/energies.h"

namespace polycube::constraints {

struct Constraint {
  std::string name;                      ///< optional, for the report
  bool sharp = true;                     ///< sharp (polycube edge) or flat (inside a face)
  double weight = 0;                     ///< omega; 0 = ConstraintOptions::weight
  std::vector<std::array<int, 2>> edges; ///< input vertex id pairs
  std::vector<int> faces;                ///< input triangle ids (a region)
  std::string group;                     ///< a painted region by name (OBJ group, PLY region value)
};

/// Adds to every constraint with a group the triangles of that group (face_group: one name per
/// input triangle, from the reader). Throws Error(Usage) naming a group that no triangle has.
void resolve_groups(std::vector<Constraint>& c, const std::vector<std::string>& face_group);

struct ConstraintOptions {
  /// Default omega of Eqs. 12-13, per constrained edge. The solver's other terms are normalized
  /// (E1 by the boundary area, ARAP by the volume), so this is relative to them. On the ramp
  /// example (11 edges, see tests) 0.1, 1 and 10 all give a polycube edge (worst error 0.05, 0.016,
  /// 0.002 degrees) but stiffer terms cost factorizations (21, 41, 61): 1 is the compromise. The
  /// paper's Fig. 2 uses 1e3 in its own units.
  double weight = 1;
};

/// Reads a constraint file. Throws Error(Parse) naming the file and the entry at fault.
std::vector<Constraint> read_constraints(const std::string& path);

/// Writes constraints in the format above. Throws Error(Output).
void write_constraints(const std::string& path, const std::vector<Constraint>& c);

/// Sharp features of a triangle surface: edges whose adjacent normals differ by more than
/// angle_deg, as one sharp constraint per feature curve (chains of sharp edges split where other
/// than two sharp edges meet), named "feature N".
std::vector<Constraint> detect_features(const SurfaceMesh& s, double angle_deg);

/// The surface edges a constraint acts on (input vertex ids, a < b): its edges, plus for a region
/// the edges inside it (flat) or on its border (sharp). Throws Error(Usage) naming the constraint
/// when an id is out of range or a pair is not an edge of s.
std::vector<std::array<int, 2>> constraint_edges(const Constraint& c, const SurfaceMesh& s, int index);

/// Constraints carried to the tet boundary B (outward, over positions V) as energy terms on
/// deform::face_pairs(B).
struct Mapped {
  std::vector<deform::EdgeConstraint> terms;
  std::vector<int> owner;          ///< constraint index of each term
  std::vector<int> input_edges;    ///< per constraint: surface edges it names
  std::vector<int> mapped_edges;   ///< per constraint: boundary edges it got
};

/// Maps the constraints on surface s to the boundary B of a tet mesh over V. A surface edge whose
/// end positions are boundary vertices joined by a boundary edge maps to that edge (the
/// tetrahedralization kept the surface); the others (remeshed surface) map to the boundary edges
/// whose ends and midpoint lie on their polyline, within 1% of their mean length (a new edge may
/// span several input edges).
Mapped map_to_boundary(const std::vector<Constraint>& c, const SurfaceMesh& s, const MatX3d& V, const MatX3i& B,
                       const std::vector<deform::FacePair>& pairs, const ConstraintOptions& opt = {});

/// Angle in degrees between the normals of the two triangles of every term (0 = flat, 90 = a
/// right polycube edge) on positions X.
std::vector<double> normal_angles_deg(const Mapped& m, const MatX3d& X, const MatX3i& B,
                                      const std::vector<deform::FacePair>& pairs);

}  // namespace polycube::constraints
