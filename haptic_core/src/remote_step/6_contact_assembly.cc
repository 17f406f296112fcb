#include <algorithm>
#include <cmath>

#include "haptic_core/contact_assembly.h"

namespace ht {
namespace {

// One contact's PenaltyWrench at q0, as the operator's loop evaluates it there (its planes may
// blend at q0).
Wrench WrenchAtQ0(const ContactLinearization& c) noexcept {
  PenetrationGradient J;
  const double depth = ContactDepthAt(c, Twist{}, &J);
  return PenaltyWrench(depth, J, c.stiffness_n_per_m);
}

}  // namespace

int AssembleContactModel(std::span<const ContactLinearization> contacts,
                         ContactModel& model) noexcept {
  int appended = 0;
  for (const ContactLinearization& lin : contacts) {
    if (!std::isfinite(lin.depth_m)) continue;  // no overlap of the patches on the window
    if (model.num_contacts >= kMaxContacts) break;
    model.contacts[model.num_contacts++] = lin;
    model.F_T_W_at_q0 += WrenchAtQ0(lin);
    ++appended;
  }
  return appended;
}

Wrench ContactModelWrenchAtQ0(const ContactModel& model) noexcept {
  Wrench F{};
  const int n = std::clamp(model.num_contacts, 0, kMaxContacts);
  for (int i = 0; i < n; ++i) F += WrenchAtQ0(model.contacts[static_cast<std::size_t>(i)]);
  return F;
}

}  // namespace ht
