#include "haptic_core/contact_assembly.h"

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

}  // namespace ht
