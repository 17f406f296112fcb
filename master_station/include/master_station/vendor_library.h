#pragma once
// A device vendor's run-time library loaded with dlopen at Open, so that master_station builds and
// runs without it: the Force Dimension DHD library (force_dimension.h) and OpenHaptics' HD library
// (openhaptics.h). Each missing piece (the library, one of its C symbols) throws a message that
// names the device, the library or symbol, and what to install.

#include <string>
#include <vector>

namespace ht {

/// What a backend says about the library it needs.
struct VendorLibrarySpec {
  std::string device;  ///< Device family for messages, e.g. "Force Dimension".
  /// File names tried in order when no path is given (dlopen's search: LD_LIBRARY_PATH,
  /// /etc/ld.so.cache, /lib, /usr/lib), e.g. {"libdhd.so", "libdhd.so.3"}.
  std::vector<std::string> names;
  /// What to install and how to point at it, ending a message, e.g. "Install the Force Dimension
  /// SDK ... or give the library with --device-library PATH".
  std::string install_hint;
};

/// An open shared library (RTLD_NOW | RTLD_LOCAL), closed on destruction. Not copyable.
class VendorLibrary {
 public:
  /// Opens `path` when it is non-empty, else the first of `spec.names` that dlopen finds. Throws
  /// std::runtime_error "<device>: cannot load <what> (<dlerror>). <install_hint>".
  VendorLibrary(const VendorLibrarySpec& spec, const std::string& path);
  ~VendorLibrary();
  VendorLibrary(const VendorLibrary&) = delete;
  VendorLibrary& operator=(const VendorLibrary&) = delete;

  /// The C function `symbol` as a pointer of type F. Throws std::runtime_error "<device>: <file>
  /// has no <symbol> (<dlerror>); ... <install_hint>" when the library lacks it (an SDK too old or
  /// not the vendor's).
  template <typename F>
  F Require(const char* symbol) const {
    return reinterpret_cast<F>(RequireAddress(symbol));
  }
  /// The C function `symbol` as a pointer of type F, or nullptr when the library lacks it (for
  /// functions that only newer SDKs have).
  template <typename F>
  F Find(const char* symbol) const noexcept {
    return reinterpret_cast<F>(FindAddress(symbol));
  }
  /// The name or path that was loaded.
  const std::string& file() const noexcept { return file_; }

 private:
  void* RequireAddress(const char* symbol) const;
  void* FindAddress(const char* symbol) const noexcept;

  std::string device_;
  std::string install_hint_;
  std::string file_;
  void* handle_ = nullptr;
};

}  // namespace ht
