// Intentionally empty: a module of this name is only its link to one system library
// (modules/CMakeLists.txt, base/lazy_library.hpp).
