#include "pv/record_support.hpp"

namespace beamctl::pv::support {

const Menu kMenuSimm{"menuSimm", {"NO", "YES", "RAW"}};
// menuConvert of base: the first three are arithmetic; the rest name breakpoint tables (their
// spelling is base's, "(ixe only)" included).
const Menu kMenuConvert{"menuConvert",
                        {"NO CONVERSION", "SLOPE", "LINEAR", "typeKdegF", "typeKdegC", "typeJdegF",
                         "typeJdegC", "typeEdegF(ixe only)", "typeEdegC(ixe only)", "typeTdegF", "typeTdegC",
                         "typeRdegF", "typeRdegC", "typeSdegF", "typeSdegC"}};

const Menu kMenuLongoutOopt{"longoutOOPT",
                            {"Every Time", "On Change", "When Zero", "When Non-zero", "Transition To Zero",
                             "Transition To Non-zero"}};

} // namespace beamctl::pv::support
