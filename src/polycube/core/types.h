// Basic array types shared by every stage.
//
// Meshes are plain arrays, as in libigl:
//   V  #V x 3 doubles, one vertex per row (input units; never rescaled in files we write)
//   F  #F x 3 ints,    one triangle per row, counter-clockwise seen from outside = outward normal
//   T  #T x 4 ints,    one tetrahedron per row, positive orientation (see tet convention below)
//   H  #H x 8 ints,    one hexahedron per row (see hex convention below)
// All indices are 0-based in memory; files use their own convention (1-based for OBJ and MEDIT).
//
// Tetrahedron (MEDIT / VTK_TETRA order), positive when det[v1-v0, v2-v0, v3-v0] > 0:
//
//            3
//           /|\          v3 lies on the side of face (0,1,2) towards which the
//          / | \         right-hand normal of (v0,v1,v2) points.
//         /  |  \        Local face i is the face opposite vertex i, oriented outward:
//        0---|---2         f0=(1,2,3) f1=(0,3,2) f2=(0,1,3) f3=(0,2,1)
//         \  |  /
//          \ | /
//            1
//
// Hexahedron (MEDIT / VTK_HEXAHEDRON order): bottom quad 0-1-2-3 counter-clockwise seen
// from the top quad 4-5-6-7, vertex i+4 above vertex i:
//
//        7-------6
//       /|      /|
//      4-------5 |
//      | 3-----|-2
//      |/      |/
//      0-------1
//
// Polycube chart label code (used from the polycube stage on): 0..5 = +X, -X, +Y, -Y, +Z, -Z.
#pragma once
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <string>
#include <vector>

namespace polycube {

using MatX3d = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;
using MatX3i = Eigen::Matrix<int, Eigen::Dynamic, 3, Eigen::RowMajor>;
using MatX4i = Eigen::Matrix<int, Eigen::Dynamic, 4, Eigen::RowMajor>;
using MatX8i = Eigen::Matrix<int, Eigen::Dynamic, 8, Eigen::RowMajor>;
using Vec3 = Eigen::Vector3d;

/// Local faces of a tetrahedron, face i opposite vertex i, oriented outward for a positive tet.
inline constexpr int kTetFaces[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}};

/// Chart labels: 0..5 = +X, -X, +Y, -Y, +Z, -Z. axis = label / 2, sign = label % 2 ? -1 : +1.
enum Label : int { kPosX = 0, kNegX = 1, kPosY = 2, kNegY = 3, kPosZ = 4, kNegZ = 5 };

/// A triangle surface mesh.
struct SurfaceMesh {
  MatX3d V;
  MatX3i F;
};

/// A tetrahedral mesh. `boundary` are its boundary triangles, oriented outward.
struct TetMesh {
  MatX3d V;
  MatX4i T;
  MatX3i boundary;
};

}  // namespace polycube
