/* An empty translation unit for a module library that has no sources yet. */
typedef int fxc_empty_translation_unit;
