#include "haptic_core/contact_assembly.h"

#include <algorithm>
#include <cmath>

namespace ht {

int AssembleContactModel(std::span<const ContactLinearization> contacts,
                         ContactModel& model) noexcept {
  int appended = 0;
  for (const ContactLinearization& lin : contacts) {
    if (!std::isfinite(lin.depth_m)) continue;  // no overlap of the patches on the window
    if (model.num_contacts >= kMaxContacts) break;
    model.contacts[model.num_contacts++] = lin;
    // At q0, as the operator's loop evaluates it (a contact's planes may blend there).
    PenetrationGradient J;
    const double depth = ContactDepthAt(lin, Twist{}, &J);
    model.F_T_W_at_q0 += PenaltyWrench(depth, J, lin.stiffness_n_per_m);
    ++appended;
  }
  return appended;
}

Wrench ContactModelWrenchAtQ0(const ContactModel& model) noexcept {
  Wrench F{};
  const int n = std::clamp(model.num_contacts, 0, kMaxContacts);
  for (int i = 0; i < n; ++i) {
    const ContactLinearization& c = model.contacts[static_cast<std::size_t>(i)];
    PenetrationGradient J;
    const double depth = ContactDepthAt(c, Twist{}, &J);
    F += PenaltyWrench(depth, J, c.stiffness_n_per_m);
  }
  return F;
}

}  // namespace ht
