#pragma once
/// \file error.h
/// Typed errors. The library throws these and never exits; `main` prints one line.

#include <stdexcept>
#include <string>

namespace voxcone {

/// Base of every voxcone error.
class Error : public std::runtime_error {
public:
  using std::runtime_error::runtime_error;
};

/// Bad scene description: the message names the file and the JSON path or line.
class SceneError : public Error {
public:
  SceneError(const std::string& file, const std::string& where, const std::string& what)
      : Error(file + (where.empty() ? "" : ": " + where) + ": " + what) {}
};

/// Malformed or unreadable mesh file (OBJ, PLY): the message names the file and line/element.
class MeshError : public Error {
public:
  MeshError(const std::string& file, const std::string& what) : Error(file + ": " + what) {}
};

/// Image read/write failure.
class ImageError : public Error {
public:
  using Error::Error;
};

/// Impossible settings (resolution, spp, threads, unknown method...).
class SettingsError : public Error {
public:
  using Error::Error;
};

/// The work was done and written, but what was asked of it was not reached (a render's
/// --target-error or --time-budget): the CLI exits 3 with this message.
class NotMetError : public Error {
public:
  using Error::Error;
};

/// A long stage was cancelled through its Progress object.
class CancelledError : public Error {
public:
  CancelledError() : Error("cancelled") {}
  explicit CancelledError(const std::string& what) : Error(what) {}
};

}  // namespace voxcone
