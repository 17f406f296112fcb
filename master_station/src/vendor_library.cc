// A device vendor's run-time library through dlopen/dlsym (vendor_library.h).

#include "master_station/vendor_library.h"

#include <dlfcn.h>

#include <stdexcept>

namespace ht {
namespace {

std::string LastDlError() {
  const char* e = dlerror();
  return e ? e : "unknown error";
}

}  // namespace

VendorLibrary::VendorLibrary(const VendorLibrarySpec& spec, const std::string& path)
    : device_(spec.device), install_hint_(spec.install_hint) {
  if (!path.empty()) {
    handle_ = dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
    if (!handle_) {
      throw std::runtime_error(device_ + ": cannot load " + path + " (" + LastDlError() + "). " +
                               install_hint_);
    }
    file_ = path;
    return;
  }
  std::string tried, first_error;
  for (const std::string& name : spec.names) {
    handle_ = dlopen(name.c_str(), RTLD_NOW | RTLD_LOCAL);
    if (handle_) {
      file_ = name;
      return;
    }
    const std::string error = LastDlError();
    if (first_error.empty()) first_error = error;
    tried += (tried.empty() ? "" : ", ") + name;
  }
  throw std::runtime_error(device_ + ": cannot load its library (tried " + tried + "; " +
                           first_error + "). " + install_hint_);
}

VendorLibrary::~VendorLibrary() {
  if (handle_) dlclose(handle_);
}

void* VendorLibrary::RequireAddress(const char* symbol) const {
  dlerror();  // clear
  void* address = dlsym(handle_, symbol);
  if (!address) {
    throw std::runtime_error(device_ + ": " + file_ + " has no " + symbol + " (" + LastDlError() +
                             "); it is not the vendor's library or is too old. " + install_hint_);
  }
  return address;
}

void* VendorLibrary::FindAddress(const char* symbol) const noexcept {
  return dlsym(handle_, symbol);
}

}  // namespace ht
