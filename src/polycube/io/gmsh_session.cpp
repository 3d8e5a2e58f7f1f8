#include "polycube/io/gmsh_session.h"

#include <gmsh.h>

namespace polycube::io {

static std::mutex& gmsh_mutex() {
  static std::mutex m;
  return m;
}

GmshSession::GmshSession() : lock_(gmsh_mutex()) {
  gmsh::initialize(0, nullptr, false);
  gmsh::option::setNumber("General.Terminal", 0);
  gmsh::option::setNumber("General.Verbosity", 2);
  gmsh::logger::start();
}

GmshSession::~GmshSession() {
  try {
    gmsh::logger::stop();
    gmsh::finalize();
  } catch (...) {
  }
}

std::vector<std::string> GmshSession::log() const {
  std::vector<std::string> l;
  try {
    gmsh::logger::get(l);
  } catch (...) {
  }
  return l;
}

std::string GmshSession::last_error() const {
  std::string e;
  try {
    gmsh::logger::getLastError(e);
  } catch (...) {
  }
  return e;
}

std::string GmshSession::describe(const std::string& what) const {
  std::string e = last_error();
  if (e.empty()) e = what;
  // Gmsh prefixes messages with "Error   : "; drop it.
  const std::string p = "Error   : ";
  if (e.rfind(p, 0) == 0) e = e.substr(p.size());
  return e;
}

}  // namespace polycube::io
