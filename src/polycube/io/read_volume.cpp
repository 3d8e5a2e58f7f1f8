// Readers of volume formats with our own parsers: MEDIT .mesh (ASCII) and legacy VTK.
#include <algorithm>
#include <cstring>
#include <map>

#include "polycube/core/error.h"
#include "polycube/io/builder.h"
#include "polycube/io/readers.h"
#include "polycube/io/text_reader.h"

namespace polycube::io {

// ---------------------------------------------------------------- MEDIT
MeshData read_medit(const std::string& path) {
  std::string data = read_file(path);
  if (data.find('\0') != std::string::npos)
    throw Error(ErrorKind::Parse, path + ": binary MEDIT (.meshb) is not supported; convert to ASCII .mesh");
  TextReader r(data, path, '#');
  Builder b;
  long long nv = -1;
  bool ended = false;
  // Sections we read past: number of integers/reals per entry.
  const std::map<std::string, int> skip = {
      {"Edges", 3}, {"Corners", 1}, {"Ridges", 1}, {"RequiredVertices", 1}, {"RequiredEdges", 1},
      {"RequiredTriangles", 1}, {"RequiredQuadrilaterals", 1}, {"Normals", 3}, {"NormalAtVertices", 2},
      {"Tangents", 3}, {"TangentAtVertices", 2}, {"TangentAtEdges", 3}, {"Prisms", 7}, {"Pyramids", 6},
      {"NormalAtTriangleVertices", 3}, {"NormalAtQuadrilateralVertices", 3}, {"Identifier", 0}, {"Geometry", 0}};
  auto vid = [&](const char* what, long long elem) {
    long long i = r.read_int(what);
    if (nv < 0) r.fail(std::string(what) + " before the Vertices section");
    if (i < 1 || i > nv)
      r.fail(std::string(what) + " " + std::to_string(i) + " of element " + std::to_string(elem + 1) +
             " out of range [1, " + std::to_string(nv) + "]");
    return static_cast<int>(i - 1);
  };
  std::string_view kw;
  bool have_version = false;
  while (r.next(kw)) {
    std::string k(kw);
    if (k == "MeshVersionFormatted") {
      long long v = r.read_int("mesh version");
      if (v < 1 || v > 4) r.fail("unsupported MeshVersionFormatted " + std::to_string(v));
      have_version = true;
    } else if (k == "Dimension") {
      long long d = r.read_int("dimension");
      if (d != 3) r.fail("only 3D meshes are supported (Dimension " + std::to_string(d) + ")");
    } else if (k == "Vertices") {
      if (nv >= 0) r.fail("second Vertices section");
      nv = r.read_int("vertex count");
      if (nv < 0) r.fail("negative vertex count");
      for (long long i = 0; i < nv; ++i) {
        double x = r.read_double("vertex x");
        int line = r.line();
        double y = r.read_double("vertex y"), z = r.read_double("vertex z");
        r.read_int("vertex reference");
        b.add_vertex(x, y, z, line);
      }
    } else if (k == "Triangles") {
      long long n = r.read_int("triangle count");
      for (long long i = 0; i < n; ++i) {
        int a = vid("triangle vertex", i);
        int line = r.line();
        int c1 = vid("triangle vertex", i), c2 = vid("triangle vertex", i);
        r.read_int("triangle reference");
        b.add_triangle(a, c1, c2, static_cast<int>(i), line);
      }
    } else if (k == "Quadrilaterals") {
      long long n = r.read_int("quadrilateral count");
      for (long long i = 0; i < n; ++i) {
        for (int c = 0; c < 4; ++c) b.q.push_back(vid("quadrilateral vertex", i));
        r.read_int("quadrilateral reference");
      }
    } else if (k == "Tetrahedra") {
      long long n = r.read_int("tetrahedron count");
      for (long long i = 0; i < n; ++i) {
        for (int c = 0; c < 4; ++c) b.t.push_back(vid("tetrahedron vertex", i));
        r.read_int("tetrahedron reference");
      }
    } else if (k == "Hexahedra") {
      long long n = r.read_int("hexahedron count");
      for (long long i = 0; i < n; ++i) {
        for (int c = 0; c < 8; ++c) b.h.push_back(vid("hexahedron vertex", i));
        r.read_int("hexahedron reference");
      }
    } else if (k == "End") {
      ended = true;
      break;
    } else if (skip.count(k)) {
      int per = skip.at(k);
      long long n = per ? r.read_int("entry count") : 0;
      for (long long i = 0; i < n * per; ++i) r.read_double(k.c_str());
    } else {
      r.fail("unknown MEDIT keyword '" + k + "'");
    }
  }
  if (!have_version) throw Error(ErrorKind::Parse, path + ":1: not a MEDIT file (no MeshVersionFormatted)");
  (void)ended;  // 'End' is optional in practice
  MeshData m;
  m.path = path;
  m.format = "medit";
  b.finish(m);
  return m;
}

// ---------------------------------------------------------------- VTK legacy
namespace {
// A cursor that reads tokens in ASCII files and big-endian raw arrays in BINARY ones.
struct VtkCursor {
  const std::string& d;
  const std::string& path;
  size_t pos = 0;
  int line = 1;
  bool binary = false;

  [[noreturn]] void fail(const std::string& m) const {
    throw Error(ErrorKind::Parse, path + ":" + std::to_string(line) + ": " + m);
  }
  bool token(std::string& t) {
    while (pos < d.size() && std::isspace(static_cast<unsigned char>(d[pos]))) {
      if (d[pos] == '\n') ++line;
      ++pos;
    }
    if (pos >= d.size()) return false;
    size_t b = pos;
    while (pos < d.size() && !std::isspace(static_cast<unsigned char>(d[pos]))) ++pos;
    t = d.substr(b, pos - b);
    return true;
  }
  std::string expect(const char* what) {
    std::string t;
    if (!token(t)) fail(std::string("unexpected end of file while reading ") + what + " (file truncated?)");
    return t;
  }
  long long integer(const char* what) {
    std::string t = expect(what);
    long long v;
    if (!parse_int(t, v)) fail(std::string("expected an integer for ") + what + ", found '" + t + "'");
    return v;
  }
  std::string rest_of_line() {
    size_t e = d.find('\n', pos);
    if (e == std::string::npos) e = d.size();
    std::string s = d.substr(pos, e - pos);
    pos = e < d.size() ? e + 1 : e;
    ++line;
    return s;
  }
  // Reads n values of a VTK data type into doubles.
  void array(const std::string& type, size_t n, std::vector<double>& out, const char* what) {
    out.resize(n);
    if (!binary) {
      for (size_t i = 0; i < n; ++i) {
        std::string t = expect(what);
        if (!parse_double(t, out[i])) fail(std::string("expected a number in ") + what + ", found '" + t + "'");
      }
      return;
    }
    int sz;
    if (type == "float") sz = 4;
    else if (type == "double") sz = 8;
    else if (type == "int" || type == "unsigned_int") sz = 4;
    else if (type == "long" || type == "vtktypeint64" || type == "unsigned_long" || type == "vtktypeuint64") sz = 8;
    else if (type == "short" || type == "unsigned_short") sz = 2;
    else if (type == "char" || type == "unsigned_char") sz = 1;
    else fail("unsupported VTK data type '" + type + "'");
    // Binary data starts after the newline that ends the header line.
    size_t nl = d.find('\n', pos);
    if (nl == std::string::npos) fail(std::string("missing binary data for ") + what);
    pos = nl + 1;
    ++line;
    if (pos + n * sz > d.size())
      fail(std::string("binary ") + what + " needs " + std::to_string(n * sz) + " bytes, file has " +
           std::to_string(d.size() - pos) + " left (truncated?)");
    for (size_t i = 0; i < n; ++i) {
      unsigned char b[8];
      std::memcpy(b, d.data() + pos + i * sz, sz);
      std::reverse(b, b + sz);  // big-endian on disk
      double v = 0;
      if (type == "float") { float f; std::memcpy(&f, b, 4); v = f; }
      else if (type == "double") { std::memcpy(&v, b, 8); }
      else if (type == "int") { int32_t x; std::memcpy(&x, b, 4); v = x; }
      else if (type == "unsigned_int") { uint32_t x; std::memcpy(&x, b, 4); v = x; }
      else if (type == "short") { int16_t x; std::memcpy(&x, b, 2); v = x; }
      else if (type == "unsigned_short") { uint16_t x; std::memcpy(&x, b, 2); v = x; }
      else if (type == "char") { v = static_cast<int8_t>(b[0]); }
      else if (type == "unsigned_char") { v = b[0]; }
      else if (type == "unsigned_long" || type == "vtktypeuint64") { uint64_t x; std::memcpy(&x, b, 8); v = static_cast<double>(x); }
      else { int64_t x; std::memcpy(&x, b, 8); v = static_cast<double>(x); }
      out[i] = v;
    }
    pos += n * sz;
  }
};
}  // namespace

MeshData read_vtk(const std::string& path) {
  std::string data = read_file(path);
  VtkCursor c{data, path};
  std::string l1 = c.rest_of_line();
  if (l1.rfind("# vtk DataFile", 0) != 0) { c.line = 1; c.fail("not a legacy VTK file (first line must be '# vtk DataFile Version x.x')"); }
  c.rest_of_line();  // title
  std::string enc = c.expect("ASCII or BINARY");
  if (enc == "BINARY") c.binary = true;
  else if (enc != "ASCII") c.fail("expected ASCII or BINARY, found '" + enc + "'");
  if (c.expect("DATASET") != "DATASET") c.fail("expected 'DATASET'");
  std::string ds = c.expect("dataset type");
  if (ds != "UNSTRUCTURED_GRID" && ds != "POLYDATA")
    c.fail("unsupported dataset '" + ds + "' (UNSTRUCTURED_GRID or POLYDATA)");
  Builder b;
  std::vector<double> pts, conn, offs, types;
  bool have_points = false, new_layout = false;
  long long ncells = -1;
  std::string kw;
  std::vector<std::vector<int>> cells;  // per cell its vertex ids
  auto read_cells_old = [&](long long n, long long size, const char* what) {
    std::vector<double> a;
    c.array("int", static_cast<size_t>(size), a, what);
    size_t p = 0;
    for (long long i = 0; i < n; ++i) {
      if (p >= a.size()) c.fail(std::string(what) + " list shorter than announced");
      long long k = static_cast<long long>(a[p++]);
      if (k < 0 || p + k > a.size()) c.fail(std::string(what) + " " + std::to_string(i) + " has a bad vertex count");
      std::vector<int> cell;
      for (long long j = 0; j < k; ++j) cell.push_back(static_cast<int>(a[p++]));
      cells.push_back(std::move(cell));
    }
  };
  while (c.token(kw)) {
    if (kw == "POINTS") {
      long long n = c.integer("point count");
      std::string type = c.expect("point data type");
      c.array(type, static_cast<size_t>(n) * 3, pts, "POINTS");
      for (long long i = 0; i < n; ++i) b.add_vertex(pts[3 * i], pts[3 * i + 1], pts[3 * i + 2], 0);
      have_points = true;
    } else if (kw == "CELLS" || kw == "POLYGONS") {
      long long n = c.integer("cell count");
      long long size = c.integer("cell list size");
      // VTK 5.1: "CELLS n+1 m" then OFFSETS and CONNECTIVITY arrays.
      size_t save = c.pos;
      int save_line = c.line;
      std::string next;
      c.token(next);
      if (next == "OFFSETS") {
        new_layout = true;
        std::string t1 = c.expect("offset type");
        c.array(t1, static_cast<size_t>(n), offs, "OFFSETS");
        if (c.expect("CONNECTIVITY") != "CONNECTIVITY") c.fail("expected CONNECTIVITY after OFFSETS");
        std::string t2 = c.expect("connectivity type");
        c.array(t2, static_cast<size_t>(size), conn, "CONNECTIVITY");
        for (long long i = 0; i + 1 < n; ++i) {
          std::vector<int> cell;
          for (long long j = static_cast<long long>(offs[i]); j < static_cast<long long>(offs[i + 1]); ++j) {
            if (j < 0 || j >= size) c.fail("OFFSETS point outside CONNECTIVITY");
            cell.push_back(static_cast<int>(conn[j]));
          }
          cells.push_back(std::move(cell));
        }
        ncells = n - 1;
      } else {
        c.pos = save;
        c.line = save_line;
        read_cells_old(n, size, kw == "CELLS" ? "cell" : "polygon");
        ncells = n;
      }
      if (kw == "POLYGONS") types.assign(cells.size(), 7.0);
    } else if (kw == "CELL_TYPES") {
      long long n = c.integer("cell type count");
      c.array("int", static_cast<size_t>(n), types, "CELL_TYPES");
    } else if (kw == "VERTICES" || kw == "LINES" || kw == "TRIANGLE_STRIPS") {
      long long n = c.integer("count");
      long long size = c.integer("size");
      std::vector<double> skip;
      c.array("int", static_cast<size_t>(size), skip, kw.c_str());
      (void)n;
    } else if (kw == "CELL_DATA" || kw == "POINT_DATA" || kw == "FIELD" || kw == "METADATA") {
      break;  // attributes: not geometry
    } else {
      c.fail("unexpected VTK keyword '" + kw + "'");
    }
  }
  (void)new_layout;
  if (!have_points) c.fail("no POINTS section");
  if (ncells < 0) c.fail("no CELLS or POLYGONS section");
  if (types.size() != cells.size())
    c.fail("CELL_TYPES has " + std::to_string(types.size()) + " entries for " + std::to_string(cells.size()) + " cells");
  const long long nv = b.num_vertices();
  int nface = 0;
  for (size_t i = 0; i < cells.size(); ++i) {
    for (int v : cells[i])
      if (v < 0 || v >= nv)
        throw Error(ErrorKind::Parse, path + ": cell " + std::to_string(i) + " vertex index " + std::to_string(v) +
                                          " out of range [0, " + std::to_string(nv) + ")");
    const int t = static_cast<int>(types[i]);
    const size_t k = cells[i].size();
    auto need = [&](size_t n) {
      if (k != n)
        throw Error(ErrorKind::Parse, path + ": cell " + std::to_string(i) + " of type " + std::to_string(t) + " has " +
                                          std::to_string(k) + " vertices, expected " + std::to_string(n));
    };
    switch (t) {
      case 1: case 2: case 3: case 4: break;  // vertices and lines
      case 5: need(3); b.add_triangle(cells[i][0], cells[i][1], cells[i][2], nface++, 0); break;
      case 7:
        if (k < 3) throw Error(ErrorKind::Parse, path + ": polygon " + std::to_string(i) + " has fewer than 3 vertices");
        b.add_polygon(cells[i], nface++, 0);
        break;
      case 9: need(4); b.q.insert(b.q.end(), cells[i].begin(), cells[i].end()); break;
      case 10: need(4); b.t.insert(b.t.end(), cells[i].begin(), cells[i].end()); break;
      case 12: need(8); b.h.insert(b.h.end(), cells[i].begin(), cells[i].end()); break;
      default:
        throw Error(ErrorKind::Parse, path + ": cell " + std::to_string(i) + " has unsupported VTK cell type " +
                                          std::to_string(t) + " (supported: 5 triangle, 7 polygon, 9 quad, 10 tetra, 12 hexahedron)");
    }
  }
  MeshData m;
  m.path = path;
  m.format = c.binary ? "vtk-binary" : "vtk-ascii";
  b.finish(m);
  return m;
}

}  // namespace polycube::io
