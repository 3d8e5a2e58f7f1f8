// RAII access to the Gmsh library. Gmsh is a process-wide singleton that is not re-entrant and that
// stays in a broken state after it throws, so every use opens its own session (initialize on entry,
// finalize on exit) under a global mutex, with Gmsh's terminal output off and its log captured.
#pragma once
#include <mutex>
#include <string>
#include <vector>

#include "polycube/core/error.h"

namespace polycube::io {

class GmshSession {
 public:
  GmshSession();
  ~GmshSession();
  GmshSession(const GmshSession&) = delete;
  GmshSession& operator=(const GmshSession&) = delete;

  /// Messages Gmsh logged since the session started.
  std::vector<std::string> log() const;
  /// The last error Gmsh logged, or "" if none.
  std::string last_error() const;

  /// Runs f(); turns Gmsh's exceptions (thrown as std::string or std::exception) into
  /// Error(kind, context + ": " + gmsh message).
  template <class F>
  void run(ErrorKind kind, const std::string& context, F&& f) {
    try {
      f();
    } catch (const std::string& e) {
      throw Error(kind, context + ": " + describe(e));
    } catch (const Error&) {
      throw;
    } catch (const std::exception& e) {
      throw Error(kind, context + ": " + describe(e.what()));
    }
  }

 private:
  std::string describe(const std::string& what) const;
  std::unique_lock<std::mutex> lock_;
};

struct Builder;

/// Copies the mesh of the current Gmsh model (all entities) into `b`: triangles (and, with
/// `surface_only`, quads split into triangles) or quads, tets, hexes; higher-order elements keep
/// their corner nodes. Throws Error(Parse) naming `path` for other element types. Call inside run().
void collect_gmsh_mesh(Builder& b, const std::string& path, bool surface_only);

/// Bounding-box diagonal of the current Gmsh model. Call inside run().
double gmsh_model_diagonal();

}  // namespace polycube::io
