#include "polycube/pipeline/measure.h"

#include "polycube/core/error.h"
#include "polycube/hex/quality.h"
#include "polycube/io/readers.h"
#include "polycube/quad/quad.h"
#include "polycube/validate/tetmesh.h"

namespace polycube {

namespace {

// The surface of a mesh file: its triangles (and quads), or the boundary of its volume cells.
SurfaceMesh surface_of(const MeshData& m) {
  SurfaceMesh s;
  s.V = m.V;
  if (m.H.rows() > 0) {
    s.F = hex::triangulate_quads(hex::boundary_quads(m.H));  // the hex mesh's boundary
  } else if (m.T.rows() > 0) {
    s.F = tet_boundary(m.T, m.path);
  } else {
    const MatX3i FQ = hex::triangulate_quads(m.Q);
    s.F.resize(m.F.rows() + FQ.rows(), 3);
    s.F << m.F, FQ;
  }
  return s;
}

}  // namespace

void add_hausdorff(nlohmann::json& j, const hex::Hausdorff& d, double diag, const std::string& key) {
  auto point = [](const Vec3& p) { return nlohmann::json::array({p.x(), p.y(), p.z()}); };
  j["hausdorff"] = d.max;
  j["hausdorff_rel"] = d.max / diag;
  j["hausdorff_" + key + "_to_input"] = d.a_to_b;
  j["hausdorff_input_to_" + key] = d.b_to_a;
  j["hausdorff_" + key + "_to_input_at"] = point(d.a_to_b_at);
  j["hausdorff_input_to_" + key + "_at"] = point(d.b_to_a_at);
  j["mean_distance_rel"] = 0.5 * (d.mean_a_to_b + d.mean_b_to_a) / diag;
}

nlohmann::json measure_mesh(const MeasureOptions& opt, const Hooks& hooks) {
  Stopwatch sw;
  hooks.info("reading " + opt.path);
  const MeshData m = io::read_mesh(opt.path, {}, true);
  if (m.H.rows() == 0 && m.Q.rows() == 0)
    throw Error(ErrorKind::InvalidMesh, opt.path + ": no hexahedra or quadrilaterals to measure");
  const bool quads = m.H.rows() == 0;
  for (int h = 0; h < m.H.rows(); ++h)
    for (int i = 0; i < 8; ++i)
      for (int j = i + 1; j < 8; ++j)
        if (m.H(h, i) == m.H(h, j))
          throw Error(ErrorKind::InvalidMesh, opt.path + ": hex " + std::to_string(h + 1) + " repeats vertex " +
                                                  std::to_string(m.H(h, i) + 1));
  nlohmann::json j;
  j["input"] = {{"path", opt.path}, {"format", m.format}, {"vertices", m.V.rows()}};
  const char* key = quads ? "quad" : "hex";
  if (quads) {
    const quad::QuadQuality q = quad::quad_quality(m.V, m.Q);
    nlohmann::json hist = nlohmann::json::array();
    for (int c : q.histogram) hist.push_back(c);
    j[key] = {{"count", q.count},       {"sj_min", q.sj_min},         {"sj_mean", q.sj_mean},
              {"sj_max", q.sj_max},     {"inverted", q.inverted},     {"below_0_5", q.below_0_5},
              {"sj_histogram", hist}};
  } else {
    const hex::HexQuality q = hex::hex_quality(m.V, m.H);
    nlohmann::json hist = nlohmann::json::array();
    for (int c : q.histogram) hist.push_back(c);
    j[key] = {{"count", q.count},         {"sj_min", q.sj_min},         {"sj_mean", q.sj_mean},
              {"sj_max", q.sj_max},       {"inverted", q.inverted},     {"below_0_2", q.below_0_2},
              {"below_0_5", q.below_0_5}, {"sj_histogram", hist}};
  }
  if (!opt.reference.empty()) {
    hooks.info("reading reference " + opt.reference);
    const MeshData r = io::read_mesh(opt.reference);
    const SurfaceMesh rs = surface_of(r), hs = surface_of(m);
    if (rs.F.rows() == 0) throw Error(ErrorKind::InvalidMesh, opt.reference + ": no surface to compare with");
    const hex::Hausdorff d = hex::hausdorff(hs.V, hs.F, rs.V, rs.F, opt.samples);
    Eigen::AlignedBox3d box;
    for (int f = 0; f < rs.F.rows(); ++f)
      for (int k = 0; k < 3; ++k) box.extend(rs.V.row(rs.F(f, k)).transpose());
    const double diag = box.diagonal().norm();
    j["reference"] = {{"path", opt.reference}, {"bbox_diagonal", diag}};
    add_hausdorff(j[key], d, diag, key);
  }
  j["seconds"] = sw.seconds();
  return j;
}

}  // namespace polycube
