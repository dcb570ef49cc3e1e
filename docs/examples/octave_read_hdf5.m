% A manikin-hdf5/1 export in GNU Octave:
%     manikin export --db manikind.db CAMPAIGN campaign.h5 --format hdf5
%     octave-cli docs/examples/octave_read_hdf5.m campaign.h5
% load() turns groups into structs; '.' and '-' in names become '_' (datalogger.ee181_1.air_temp_c
% is datalogger_ee181_1_air_temp_c, trial c01-r1 is c01_r1). Octave's load does not read HDF5
% attributes (units, provenance): MATLAB's h5readatt does, and docs/formats.md lists them.
% MATLAB: q = h5read('campaign.h5', '/results/q_wb_w_m2');
% Heat flux: positive = heat lost by the body (skin to environment).
args = argv();
s = load(args{1});
r = s.results;
for i = 1:numel(r.case)
  printf("case %d: Q_WB = %.2f ± %.2f W/m² (n = %d)\n", r.case(i), r.q_wb_w_m2(i), r.u95_w_m2(i), r.n_replicates(i));
end
names = fieldnames(s.trials);
t = s.trials.(names{1});
last_30_min = t.t_s > max(t.t_s) - 1800;
printf("trial %s: %d rows\n", names{1}, numel(t.t_s));
printf("probe 1 air temperature, last 30 min: %.3f °C\n", mean(t.datalogger_ee181_1_air_temp_c(last_30_min)));
