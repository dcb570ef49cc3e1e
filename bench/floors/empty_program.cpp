// bench_startup's floor: a C++ program that does nothing, built with the same compiler and flags.
int main() { return 0; }
