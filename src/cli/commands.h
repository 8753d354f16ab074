#pragma once
// The `voxcone` subcommands: each file adds one to the CLI11 app.

#include <CLI/CLI.hpp>

namespace voxcone {

void addRenderCommand(CLI::App& app);
void addCompareCommand(CLI::App& app);
void addInfoCommand(CLI::App& app);
void addVoxelizeCommand(CLI::App& app);
void addStudyCommand(CLI::App& app);
void addBatchCommand(CLI::App& app);
void addGenerateCommand(CLI::App& app);
void addConvertCommand(CLI::App& app);
void addDenoiseCommand(CLI::App& app);
/// `voxcone study structures` and `study scaling` (cmd_study_structures.cpp), under `study`.
void addStructureStudies(CLI::App& study);

}  // namespace voxcone
