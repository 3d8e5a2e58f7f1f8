// One test per input error: the CLI exits with the documented code, the message names the
// problem and where, and the output folder holds nothing that could pass for a result.
#include <filesystem>

#include "polycube/io/writers.h"
#include "test_util.h"

using namespace polycube;
using namespace polycube::test;
namespace fs = std::filesystem;

namespace {

// Runs the CLI on `file` and checks exit code, message fragments and the output folder.
void expect_refused(const std::string& file, int code, const std::vector<std::string>& fragments) {
  std::string out = temp_dir("err_out");
  write_text(out + "/tetmesh.mesh", "stale result of an earlier run");
  RunResult r = run_cli("'" + file + "' -o '" + out + "'");
  EXPECT_EQ(r.code, code) << r.output;
  for (const auto& f : fragments) EXPECT_NE(r.output.find(f), std::string::npos) << "missing '" << f << "' in:\n" << r.output;
  // Only the error report remains.
  std::vector<std::string> left;
  for (auto& e : fs::directory_iterator(out)) left.push_back(e.path().filename().string());
  EXPECT_EQ(left, std::vector<std::string>{"report.json"});
  std::string rep = read_text(out + "/report.json");
  EXPECT_NE(rep.find("\"status\": \"error\""), std::string::npos) << rep;
}

std::string file(const std::string& name, const std::string& text) {
  std::string p = temp_dir("err_in") + "/" + name;
  write_text(p, text);
  return p;
}

const char* kCubeVertices = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nv 0 0 1\nv 1 0 1\nv 0 1 1\nv 1 1 1\n";
const char* kCubeFaces =
    "f 1 3 2\nf 2 3 4\nf 5 6 7\nf 6 8 7\nf 1 2 5\nf 2 6 5\nf 3 7 4\nf 4 7 8\nf 1 5 3\nf 3 5 7\nf 2 4 6\nf 4 8 6\n";

// OBJ face lines of the unit cube whose 8 vertices start at 1-based index `first`.
std::string cube_faces(int first) {
  const int tri[12][3] = {{0, 2, 1}, {1, 2, 3}, {4, 5, 6}, {5, 7, 6}, {0, 1, 4}, {1, 5, 4},
                          {2, 6, 3}, {3, 6, 7}, {0, 4, 2}, {2, 4, 6}, {1, 3, 5}, {3, 7, 5}};
  std::string s;
  for (auto& t : tri)
    s += "f " + std::to_string(first + t[0]) + " " + std::to_string(first + t[1]) + " " + std::to_string(first + t[2]) + "\n";
  return s;
}

}  // namespace

TEST(Errors, MissingFile) { expect_refused("/nonexistent/x.obj", 3, {"no such file"}); }

TEST(Errors, EmptyFile) { expect_refused(file("empty.obj", ""), 3, {"empty.obj", "file is empty"}); }

TEST(Errors, UnknownExtension) { expect_refused(file("a.xyz", "1 2 3"), 2, {"unknown file extension 'xyz'"}); }

TEST(Errors, NoFacesInObj) { expect_refused(file("v.obj", "v 0 0 0\nv 1 0 0\n"), 3, {"no faces"}); }

TEST(Errors, MalformedNumberWithLine) {
  expect_refused(file("bad.obj", "v 0 0 0\nv 1 0 0\nv 0 1 x\nf 1 2 3\n"), 3,
                 {"bad.obj:3:", "expected a number", "'x'"});
}

TEST(Errors, IndexOutOfRangeWithLine) {
  expect_refused(file("range.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n"), 3,
                 {"range.obj:4:", "index 4 out of range"});
}

TEST(Errors, TruncatedOff) {
  expect_refused(file("t.off", "OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 2\n3 0 1 3\n"), 3,
                 {"t.off", "file ends after 2 of 4 faces", "truncated"});
}

TEST(Errors, TruncatedBinaryStl) {
  auto s = box();
  std::string p = temp_dir("err_in") + "/t.stl";
  io::write_stl(p, s.V, s.F, true);
  std::string d = read_text(p);
  write_text(p, d.substr(0, d.size() - 70));
  expect_refused(p, 3, {"t.stl", "announces 12 facets", "truncated after facet 10"});
}

TEST(Errors, TruncatedMedit) {
  expect_refused(file("t.mesh", "MeshVersionFormatted 2\nDimension 3\nVertices\n4\n0 0 0 0\n1 0 0 0\n"), 3,
                 {"t.mesh:6:", "unexpected end of file", "truncated"});
}

TEST(Errors, UnknownMeditKeyword) {
  expect_refused(file("k.mesh", "MeshVersionFormatted 2\nDimension 3\nFoo\n1\n"), 3, {"k.mesh:3:", "unknown MEDIT keyword 'Foo'"});
}

TEST(Errors, MalformedMsh) {
  expect_refused(file("m.msh", "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n1 2 1 2\n2 1 0 2\n1\n"), 3, {"m.msh"});
}

TEST(Errors, NanCoordinate) {
  expect_refused(file("nan.obj", std::string("v 0 0 0\nv 1 0 nan\nv 0 1 0\nv 0 0 1\n") +
                                     "f 1 3 2\nf 1 2 4\nf 2 3 4\nf 1 4 3\n"),
                 4, {"NaN or infinite", "vertex 1 (line 2)"});
}

TEST(Errors, DegenerateFace) {
  expect_refused(file("deg.obj", std::string(kCubeVertices) + kCubeFaces + "f 1 2 2\n"), 4,
                 {"degenerate faces", "face 12 (line 21) repeats a vertex"});
}

TEST(Errors, ZeroAreaFace) {
  expect_refused(file("flat.obj", std::string(kCubeVertices) + "v 0.5 0 0\n" + kCubeFaces + "f 1 9 2\n"), 4,
                 {"degenerate faces", "face 12 (line 22) has zero area"});
}

TEST(Errors, DuplicateFace) {
  expect_refused(file("dup.obj", std::string(kCubeVertices) + kCubeFaces + "f 1 2 3\n"), 4,
                 {"duplicate faces", "face 0 (line 9) and face 12 (line 21)"});
}

TEST(Errors, NonManifoldEdge) {
  // A cube with an extra fin on edge (0,1).
  expect_refused(file("fin.obj", std::string(kCubeVertices) + "v 0.5 -1 -1\n" + kCubeFaces + "f 1 2 9\n"), 4,
                 {"non-manifold edges", "edge (0, 1) is shared by 3 faces"});
}

TEST(Errors, NonManifoldVertex) {
  // Two cubes touching at one corner.
  std::string obj = std::string(kCubeVertices) + kCubeFaces;
  obj += "v 2 1 1\nv 1 2 1\nv 2 2 1\nv 1 1 2\nv 2 1 2\nv 1 2 2\nv 2 2 2\n";
  obj += cube_faces(8);  // second cube: corner 8 (1-based) shared, then 9..15
  expect_refused(file("pinch.obj", obj), 4, {"non-manifold vertices", "vertex 7 (line 8)"});
}

TEST(Errors, OpenBoundary) {
  std::string faces = kCubeFaces;
  faces = faces.substr(faces.find('\n', faces.find('\n') + 1) + 1);  // drop the two z=0 faces
  expect_refused(file("open.obj", std::string(kCubeVertices) + faces), 4,
                 {"not closed", "4 boundary edges in 1 open loops", "loop of 4 edges"});
}

TEST(Errors, SelfIntersection) {
  // Two overlapping cubes given as one surface.
  std::string obj = kCubeVertices;
  obj += "v 0.5 0.5 0.5\nv 1.5 0.5 0.5\nv 0.5 1.5 0.5\nv 1.5 1.5 0.5\nv 0.5 0.5 1.5\nv 1.5 0.5 1.5\nv 0.5 1.5 1.5\nv 1.5 1.5 1.5\n";
  obj += kCubeFaces;
  obj += cube_faces(9);
  expect_refused(file("cross.obj", obj), 4, {"intersects itself", "faces "});
}

TEST(Errors, InvertedTetsInTetMesh) {
  expect_refused(file("inv.mesh",
                      "MeshVersionFormatted 2\nDimension 3\nVertices\n5\n0 0 0 0\n1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 -1 0\n"
                      "Tetrahedra\n2\n1 2 3 4 0\n1 2 3 5 0\nEnd\n"),
                 4, {"inverted", "tets 1"});
}

TEST(Errors, UsageErrors) {
  EXPECT_EQ(run_cli("").code, 2);
  EXPECT_EQ(run_cli("--example nosuch -o " + temp_dir("u")).code, 2);
  RunResult r = run_cli("--example sphere --until hexes -o " + temp_dir("u"));
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.output.find("unknown stage"), std::string::npos) << r.output;
  EXPECT_EQ(run_cli("--example sphere --hex --quad").code, 2);
  EXPECT_EQ(run_cli("--example sphere --tet-algorithm foo").code, 2);
  EXPECT_EQ(run_cli("--bogus").code, 2);
  EXPECT_EQ(run_cli("--example sphere --hex --until deform").code, 2);
  EXPECT_EQ(run_cli("--example sphere --hex --pillow maybe").code, 2);
  EXPECT_EQ(run_cli("measure").code, 2);
}

TEST(Errors, UnwritableOutput) {
  std::string f = temp_dir("ro") + "/file";
  write_text(f, "x");
  RunResult r = run_cli("--example sphere -o " + f + "/sub");
  EXPECT_EQ(r.code, 6) << r.output;
  EXPECT_NE(r.output.find("cannot create output folder"), std::string::npos) << r.output;
}
